#include "server/flags.h"

namespace distband {

void addServerFlags(CLI::App& app, ServerOptions* o) {
  app.add_option("--listen", o->listen_address, "address to listen on, host:port (port 0: any free port)")
      ->capture_default_str();
  app.add_option("--threads", o->compute_threads,
                 "threads computing one query (shared TBB arena workers + the query's own thread); 0 = all cores")
      ->capture_default_str();
  app.add_option("--max-queries", o->max_concurrent_queries,
                 "queries computed at once; more wait up to --queue-wait-ms, then get RESOURCE_EXHAUSTED")
      ->capture_default_str();
  app.add_option("--queue-wait-ms", o->queue_wait_ms, "how long an excess query waits for a compute slot")
      ->capture_default_str();
  app.add_option("--max-voxels", o->max_voxels_per_query, "voxel budget per query (dims.x*dims.y*dims.z)")
      ->capture_default_str();
  app.add_option("--max-upload-bytes", o->max_upload_bytes, "largest accepted upload")->capture_default_str();
  app.add_option("--cache-bytes", o->cache_bytes, "capacity of the uploaded-asset cache (LRU)")
      ->capture_default_str();
  app.add_option("--max-message-bytes", o->max_message_bytes, "largest gRPC message received or sent")
      ->capture_default_str();
  app.add_option("--batch-bytes", o->batch_bytes, "default size bound of one streamed brick batch")
      ->capture_default_str();
  app.add_option("--stream-buffer-bytes", o->stream_buffer_bytes,
                 "per-query bound on encoded messages waiting for a slow client (compute pauses beyond it)")
      ->capture_default_str();
  app.add_option("--grace-seconds", o->grace_seconds,
                 "on SIGTERM/SIGINT, how long running streams may finish before being cancelled")
      ->capture_default_str();
}

}  // namespace distband
