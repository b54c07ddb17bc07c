#include "server/server_options.h"

#include <thread>

#include <fmt/format.h>

namespace distband {

std::string ServerOptions::validate() const {
  if (listen_address.empty()) return "--listen must not be empty";
  if (compute_threads < 0 || compute_threads > 1024) return "--threads must be in [0, 1024]";
  if (max_concurrent_queries < 1 || max_concurrent_queries > 1024) return "--max-queries must be in [1, 1024]";
  if (queue_wait_ms < 0 || queue_wait_ms > 600000) return "--queue-wait-ms must be in [0, 600000]";
  if (max_voxels_per_query < 1) return "--max-voxels must be >= 1";
  if (max_message_bytes < (64u << 10) || max_message_bytes > (1u << 30))
    return "--max-message-bytes must be in [64 KiB, 1 GiB]";
  if (batch_bytes < (64u << 10) || batch_bytes > max_message_bytes)
    return "--batch-bytes must be in [64 KiB, --max-message-bytes]";
  if (stream_buffer_bytes < batch_bytes) return "--stream-buffer-bytes must be >= --batch-bytes";
  if (!(grace_seconds >= 0 && grace_seconds <= 3600)) return "--grace-seconds must be in [0, 3600]";
  return {};
}

int ServerOptions::resolvedComputeThreads() const {
  if (compute_threads > 0) return compute_threads;
  const unsigned n = std::thread::hardware_concurrency();
  return n ? int(n) : 1;
}

}  // namespace distband
