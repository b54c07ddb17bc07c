#include "server/flags.h"

namespace distband {

void addServerFlags(CLI::App& app, ServerOptions* o) {
  // Byte sizes take K/M/G/T suffixes (powers of 1024; "4G", "512MiB" and "1024" all work).
  const CLI::AsSizeValue bytes(false);
  app.add_option("--listen", o->listen_address,
                 "address to listen on, host:port (port 0: any free port); use 0.0.0.0:PORT to expose the service")
      ->capture_default_str();
  app.add_option("--threads", o->compute_threads,
                 "threads computing one query (shared TBB arena workers + the query's own thread); 0 = all cores")
      ->capture_default_str();
  app.add_option("--max-queries", o->max_concurrent_queries,
                 "queries (and upload parses) computed at once; more wait up to --queue-wait-ms, then get "
                 "RESOURCE_EXHAUSTED")
      ->capture_default_str();
  app.add_option("--queue-wait-ms", o->queue_wait_ms,
                 "how long work waits for a compute slot or for free memory in the budget")
      ->capture_default_str();
  app.add_option("--max-voxels", o->max_voxels_per_query, "voxel budget per query (dims.x*dims.y*dims.z)")
      ->capture_default_str();
  app.add_option("--max-upload-bytes", o->max_upload_bytes, "largest accepted upload")
      ->transform(bytes)
      ->capture_default_str();
  app.add_option("--max-triangles", o->max_triangles, "largest triangle count a mesh may declare or hold")
      ->capture_default_str();
  app.add_option("--max-vertices", o->max_vertices, "largest vertex count a mesh may declare or hold")
      ->capture_default_str();
  app.add_option("--memory-budget", o->memory_budget_bytes,
                 "bytes requests may use in total; every upload and query is admitted by an estimate of its peak "
                 "(0 = half of the memory this process may use, cgroup limit respected)")
      ->transform(bytes)
      ->capture_default_str();
  app.add_option("--cache-bytes", o->cache_bytes,
                 "capacity of the uploaded-asset cache (LRU), part of the memory budget (0 = budget/4, at most 1G)")
      ->transform(bytes)
      ->capture_default_str();
  app.add_option("--max-message-bytes", o->max_message_bytes, "largest gRPC message received or sent")
      ->transform(bytes)
      ->capture_default_str();
  app.add_option("--batch-bytes", o->batch_bytes, "default size bound of one streamed brick batch")
      ->transform(bytes)
      ->capture_default_str();
  app.add_option("--stream-buffer-bytes", o->stream_buffer_bytes,
                 "per-query bound on encoded messages waiting for a slow client (compute pauses beyond it)")
      ->transform(bytes)
      ->capture_default_str();
  app.add_option("--grace-seconds", o->grace_seconds,
                 "on SIGTERM/SIGINT, how long running calls may finish before being cancelled (a second signal "
                 "exits at once)")
      ->capture_default_str();
  app.add_option("--idle-timeout", o->idle_timeout_seconds,
                 "seconds an upload may receive nothing, or a query's client may read nothing, before it is cancelled")
      ->capture_default_str();
  app.add_option("--max-streams", o->max_streams,
                 "concurrent DistanceField calls of any kind; beyond it RESOURCE_EXHAUSTED at once")
      ->capture_default_str();
  app.add_option("--grpc-threads", o->grpc_threads, "cap on gRPC's threads (0 = --max-streams + 16)")
      ->capture_default_str();
  app.add_option("--tls-cert", o->tls_cert_file, "PEM certificate chain: serve TLS (with --tls-key)")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-key", o->tls_key_file, "PEM private key of --tls-cert")->check(CLI::ExistingFile);
  app.add_option("--tls-client-ca", o->tls_client_ca_file,
                 "PEM CA bundle: require client certificates signed by it (mutual TLS)")
      ->check(CLI::ExistingFile);
  app.add_option("--auth-token-file", o->auth_token_file,
                 "file with one bearer token a line: DistanceField calls need 'authorization: Bearer <token>' "
                 "(health checks do not)")
      ->check(CLI::ExistingFile);
  app.add_flag("--reflection", o->reflection, "serve gRPC server reflection (off by default)");
  app.add_option("--metrics-listen", o->metrics_listen,
                 "serve Prometheus metrics at http://ADDR/metrics, ADDR = IPV4:PORT (or [IPV6]:PORT where civetweb "
                 "has IPv6; port 0: any free port); its own port, no token: keep it on loopback or behind a network policy (off by default)");
  // Coordinator: one query over many replicas (docs/scale-out.md).
  app.add_option("--peers", o->peers,
                 "act as a coordinator: split queries into tiles computed by these replicas, a gRPC target "
                 "(ipv4:ADDR:PORT,ADDR:PORT,..., dns:///HEADLESS-SERVICE:PORT, or names NAME:PORT,NAME:PORT,...); uploads are kept here and passed on")
      ->group("Coordinator");
  app.add_option("--tile-voxels", o->tile_voxels, "largest tile; a grid with more voxels is split (whole bricks)")
      ->capture_default_str()
      ->group("Coordinator");
  app.add_option("--tiles-in-flight", o->tiles_in_flight_per_replica, "concurrent tile calls per replica")
      ->capture_default_str()
      ->group("Coordinator");
  app.add_option("--tile-retries", o->tile_retries,
                 "times a failed tile (replica gone, busy, timed out) is retried before the query fails UNAVAILABLE")
      ->capture_default_str()
      ->group("Coordinator");
  app.add_option("--tile-timeout", o->tile_timeout_seconds,
                 "seconds a tile call may take before it is retried elsewhere (the client's deadline, when sooner, wins)")
      ->capture_default_str()
      ->group("Coordinator");
  app.add_option("--tile-buffer-bytes", o->tile_buffer_bytes,
                 "per query: later segments held while an earlier one waits for slower tiles (beyond: RESOURCE_EXHAUSTED)")
      ->transform(bytes)
      ->capture_default_str()
      ->group("Coordinator");
  app.add_option("--peer-ca", o->peer_ca_file, "PEM CA bundle: reach the replicas over TLS")
      ->check(CLI::ExistingFile)
      ->group("Coordinator");
  app.add_option("--peer-tls-name", o->peer_tls_name,
                 "name the replicas' certificates are checked against (default: each address)")
      ->group("Coordinator");
  app.add_option("--peer-token-file", o->peer_token_file, "file whose first token is sent to the replicas")
      ->check(CLI::ExistingFile)
      ->group("Coordinator");
}

}  // namespace distband
