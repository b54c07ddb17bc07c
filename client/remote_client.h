// RemoteClient: the C++ client library of the distband service (distband.v1.DistanceField over gRPC).
// Contract:
//   * One RemoteClient holds one channel to `target` ("host:port"); calls may run concurrently from several
//     threads (each call has its own context). Every call returns a grpc::Status; nothing throws.
//   * query() reads the whole stream on the calling thread and hands the client core values: the Grid of the
//     header, then SegmentBricks batches (several batches may share a segment index; their lower/upper are the
//     segment's range; `last` is false on batches) in stream order, then each segment's SegmentDone. Any
//     callback returning false cancels the query (the server stops its engine); so does QueryCanceller::cancel()
//     from another thread, or the deadline. Malformed server data ends the call with INTERNAL.
//   * Uploads are client-streaming in chunks (default 1 MiB), so assets may exceed the message size limit.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/channel.h>
#include <grpcpp/client_context.h>
#include <grpcpp/support/status.h>

#include "core/brick.h"
#include "core/grid.h"
#include "core/seeds/label_volume.h"
#include "distband/v1/distband.grpc.pb.h"

namespace distband {

struct RemoteClientOptions {
  uint32_t max_message_bytes = 64u << 20;  ///< largest message accepted from the server
  size_t upload_chunk_bytes = 1u << 20;    ///< upload chunk size
  /// TLS: set `tls` to use it; `tls_root_ca_pem` empty = the system's roots. A client certificate and key (PEM)
  /// answer a server that requires mutual TLS. `tls_server_name` overrides the name checked against the server's
  /// certificate (default: the target's host).
  bool tls = false;
  std::string tls_root_ca_pem, tls_client_cert_pem, tls_client_key_pem, tls_server_name;
  /// Sent as `authorization: Bearer <token>` on every DistanceField call (not on health checks).
  std::string bearer_token;
};

/// Cancels a running query() from another thread (e.g. a SIGINT watcher). Reusable only for one query.
class QueryCanceller {
 public:
  void cancel();
  bool cancelled() const;
  std::chrono::steady_clock::time_point cancelTime() const;  ///< when cancel() was first called

 private:
  friend class RemoteClient;
  void attach(grpc::ClientContext* context);
  void detach();
  mutable std::mutex mu_;
  grpc::ClientContext* context_ = nullptr;
  bool cancelled_ = false;
  std::chrono::steady_clock::time_point cancel_time_{};
};

struct RemoteQueryCallbacks {
  /// The grid and parameters in force; called once, before any bricks.
  std::function<bool(const Grid& grid, const v1::QueryHeader& header)> on_header;
  /// One batch of decoded bricks (core types) with the payload bytes it took on the wire.
  std::function<bool(SegmentBricks&& batch, uint64_t wire_bytes)> on_bricks;
  /// The end marker of a segment (all its voxels have been delivered).
  std::function<bool(const v1::SegmentDone& done)> on_segment_done;
};

struct RemoteQueryOptions {
  std::chrono::milliseconds deadline{0};  ///< 0: none
  QueryCanceller* canceller = nullptr;
};

struct RemoteQueryResult {
  grpc::Status status;
  bool have_header = false;
  Grid grid;
  v1::QueryHeader header;
  bool have_summary = false;
  v1::QuerySummary summary;
  uint64_t messages = 0;
  uint64_t wire_bytes = 0;              ///< bytes of brick masks + values received
  double first_bricks_seconds = -1;     ///< from the call to the first brick batch (-1: none arrived)
  double first_segment_done_seconds = -1;
  double total_seconds = 0;
  bool cancelled_by_client = false;     ///< a callback or the canceller stopped it
  std::chrono::steady_clock::time_point cancel_time{};  ///< when the client cancelled (if it did)
};

/// A QueryPoints stream (see the .proto): the client's side.
struct RemotePointsCallbacks {
  /// Fills the next chunk's packed xyz (the header's coordinates type); returns false when there are no more
  /// points. Called on a writer thread of the call's own, one chunk at a time: the call is flow-controlled, so at most
  /// a few chunks are in flight. A chunk left empty after returning true is sent as is (the server refuses it).
  std::function<bool(std::string* xyz)> next_chunk;
  /// The reply header; return false to cancel.
  std::function<bool(const v1::PointsReplyHeader& header)> on_header;
  /// One chunk's results, in the chunks' order; return false to cancel.
  std::function<bool(const v1::PointsResults& results)> on_results;
};

struct RemotePointsResult {
  grpc::Status status;
  bool have_header = false;
  v1::PointsReplyHeader header;
  bool have_summary = false;
  v1::PointsSummary summary;
  uint64_t points = 0, chunks = 0;  ///< results received
  double total_seconds = 0;
  bool cancelled_by_client = false;
};

class RemoteClient {
 public:
  explicit RemoteClient(const std::string& target, RemoteClientOptions options = {});

  grpc::Status uploadMesh(const std::string& bytes, v1::MeshFormat format, const std::string& name,
                          v1::UploadReply* reply);
  /// Reads `path` (format from its extension: .obj .off .ply .stl) and uploads it.
  grpc::Status uploadMeshFile(const std::string& path, v1::UploadReply* reply);
  /// Uploads a seed or label volume with its element type.
  grpc::Status uploadVolume(const LabelVolume& volume, const std::string& name, v1::UploadReply* reply);
  /// The same from raw bytes, as the wire takes them (dims.x*dims.y*dims.z elements of `type`, x fastest; the
  /// server checks the count).
  grpc::Status uploadVolumeBytes(const Coord& dims, v1::VoxelType type, const std::vector<uint8_t>& bytes,
                                 const std::string& name, v1::UploadReply* reply);

  RemoteQueryResult query(const v1::QueryRequest& request, const RemoteQueryCallbacks& callbacks,
                          const RemoteQueryOptions& options = {});

  /// Sends `header`, then the chunks next_chunk() gives, and hands back the results as they arrive (the calling
  /// thread reads). Checks the stream's order (one header, results chunk 0, 1, ... with the points sent, one
  /// summary): INTERNAL otherwise. A false callback, the canceller or the deadline cancels the call.
  RemotePointsResult queryPoints(const v1::PointsHeader& header, const RemotePointsCallbacks& callbacks,
                                 const RemoteQueryOptions& options = {});

  grpc::Status info(v1::ServerInfo* info, std::chrono::milliseconds deadline = std::chrono::seconds(10));
  /// grpc.health.v1 Check. `service` "" asks about the whole server. *serving = status == SERVING.
  grpc::Status health(const std::string& service, bool* serving, std::string* status_name,
                      std::chrono::milliseconds deadline = std::chrono::seconds(5));

  const std::shared_ptr<grpc::Channel>& channel() const { return channel_; }

 private:
  /// A context carrying the bearer token, if any.
  void authorize(grpc::ClientContext* context) const;

  RemoteClientOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::DistanceField::Stub> stub_;
};

/// MESH_FORMAT_* from a file name's extension (case-insensitive); UNSPECIFIED when unknown.
v1::MeshFormat meshFormatFromPath(const std::string& path);

/// The Grid described by a QueryHeader.
Grid gridFromHeader(const v1::QueryHeader& header);

}  // namespace distband
