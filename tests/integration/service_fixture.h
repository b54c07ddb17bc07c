// Shared fixtures of the integration tests: an in-process DistbandServer on 127.0.0.1 port 0 driven by the real
// client library, request builders, and a stream collector that assembles the field and checks the stream order.
#pragma once

#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "client/remote_client.h"
#include "core/io/dense_field.h"
#include "server/server.h"
#include "tests/support/query_requests.h"

namespace distband {

using Clock = std::chrono::steady_clock;

inline double ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

class TestServer {
 public:
  explicit TestServer(ServerOptions o = defaults(), RemoteClientOptions client_options = {}) {
    o.listen_address = "127.0.0.1:0";
    ServerHooks hooks;
    hooks.on_query_end = [this](const QueryRecord& r) {
      std::lock_guard lock(mu_);
      records_.push_back(r);
    };
    server_ = std::make_unique<DistbandServer>(o, hooks);
    const grpc::Status s = server_->start();
    EXPECT_TRUE(s.ok()) << s.error_message();
    client_ = std::make_unique<RemoteClient>(target(), client_options);
  }
  std::string target() const { return "127.0.0.1:" + std::to_string(server_->port()); }
  static ServerOptions defaults() {
    ServerOptions o;
    o.compute_threads = 2;
    o.max_concurrent_queries = 8;
    o.memory_budget_bytes = uint64_t(4) << 30;  // the same admission on every machine
    return o;
  }
  RemoteClient& client() { return *client_; }
  DistbandServer& server() { return *server_; }
  std::vector<QueryRecord> records() {
    std::lock_guard lock(mu_);
    return records_;
  }
  /// Waits until `n` query handlers have ended (they report just before returning).
  bool waitRecords(size_t n, std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      if (records().size() >= n) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
  }

 private:
  std::unique_ptr<DistbandServer> server_;
  std::unique_ptr<RemoteClient> client_;
  std::mutex mu_;
  std::vector<QueryRecord> records_;
};

/// Everything a query delivered, assembled into a dense field, plus the order checks.
struct Streamed {
  RemoteQueryResult result;
  std::unique_ptr<DenseField> field;
  std::vector<int64_t> closest;         ///< dense closest-feature ids (-1: none) when the header announced them
  std::vector<int> batch_segments;      ///< segment index of each batch, in arrival order
  std::vector<v1::SegmentDone> done;    ///< markers in arrival order
  Clock::time_point first_batch{};
  std::string order_error;
};

inline Streamed stream(RemoteClient& client, const v1::QueryRequest& request, float background,
                std::function<bool(int batches)> keep_going = {}) {
  Streamed s;
  RemoteQueryCallbacks cb;
  cb.on_header = [&](const Grid& grid, const v1::QueryHeader& h) {
    s.field = std::make_unique<DenseField>(grid, background);
    if (h.closest_feature() != v1::CLOSEST_FEATURE_NONE) s.closest.assign(size_t(grid.voxelCount()), -1);
    return true;
  };
  cb.on_bricks = [&](SegmentBricks&& batch, uint64_t) {
    if (s.batch_segments.empty()) s.first_batch = Clock::now();
    if (!s.done.empty() && batch.index != int(s.done.back().segment()) + 1) s.order_error = "batch after its marker";
    if (!(batch.lower_world <= batch.upper_world)) s.order_error = "bad range";
    for (const Brick& b : batch.bricks) {
      for (int i = 0; i < kBrickVoxels; ++i)
        if (b.mask.test(i)) {
          const double d = std::abs(double(b.values[i]));
          const bool in = batch.index == 0 ? d <= batch.upper_world * (1 + 1e-6) + 1e-6
                                           : d > batch.lower_world * (1 - 1e-6) - 1e-6 &&
                                                 d <= batch.upper_world * (1 + 1e-6) + 1e-6;
          if (!in && s.order_error.empty())
            s.order_error = "voxel " + std::to_string(d) + " outside its segment's range (" +
                            std::to_string(batch.lower_world) + ", " + std::to_string(batch.upper_world) + "]";
        }
    }
    s.batch_segments.push_back(batch.index);
    if (!s.closest.empty())
      for (const Brick& b : batch.bricks)
        for (int i = 0; i < kBrickVoxels; ++i) {
          const Coord c = b.origin + brickLocal(i);
          if (b.mask.test(i) && s.field->grid().contains(c) && b.closest.size() == size_t(kBrickVoxels))
            s.closest[size_t(s.field->grid().denseIndex(c))] = b.closest[size_t(i)];
        }
    s.field->add(batch);
    return keep_going ? keep_going(int(s.batch_segments.size())) : true;
  };
  cb.on_segment_done = [&](const v1::SegmentDone& d) {
    if (!s.done.empty() && !(d.lower() >= s.done.back().upper() - 1e-9)) s.order_error = "segments not increasing";
    s.done.push_back(d);
    return true;
  };
  s.result = client.query(request, cb);
  return s;
}

}  // namespace distband
