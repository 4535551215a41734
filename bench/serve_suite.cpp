// The serve suite (issue #6): what a client of a real animspaced sees, against the same work done
// in process. A PMSC model (Meyer & Anderson 2007 §2) is trained on crane's even frames with the
// pmsc suite's settings (unaligned, the `animspace train-pmsc` default), written to a temporary
// repository and served by the animspaced binary on loopback; the odd frames' key points are then
// replayed through PoseService.
//
// Baselines, in process (no daemon running):
//   in_process             pmsc::evaluate_cached, one pose after another (1 thread), and in 2
//                          threads (the ceiling of a server that evaluates poses one by one here)
//   in_process_after_idle  the same with the thread asleep for 1 ms before each pose, as a server
//                          thread is between requests: whether the 7.3 MB float basis is still
//                          in cache when a request comes (on this VM, whose L3 other tenants of
//                          the host share, it is not: it is streamed from memory again)
//   in_process_after_spin  the same with 1 ms of busy-waiting instead, which tells the pause
//                          apart from the vCPU going idle
//   in_process_batch[_after_idle]
//                          pmsc::evaluate_batch on 8 poses (the stream's read-ahead window): what
//                          a server that batched a stream's frames into one GEMM would pay
//   in_process_batch64     pmsc::evaluate_batch on 64 poses, with OpenBLAS's cblas_sgemm on the same
//                          product (the float basis A, N·D × M, times the batch's coordinates,
//                          M × 64) timed right after each batch: how close the batch comes to
//                          the machine's GEMM (openblas_sgemm_poses_per_second)
//   encode_response / decode_response
//                          one EvaluateKeyPointsResponse with N·D points built and serialised /
//                          parsed: the protobuf share of every answer
// Served:
//   describe_key_points    DescribeKeyPoints, 1 thread: the unary round trip with no evaluation
//   unary                  EvaluateKeyPoints, one pose per request, points returned, sync stubs;
//                          1/4/16 client threads on one shared channel, and 4/16 with a channel
//                          (own TCP connection) per thread; unary_omit_points without the points
//   stream                 StreamKeyPoints, the odd frames looped, one writer and one reader
//                          thread per stream; 1 and 2 streams at once; stream_omit_points
//   …, work threads 1      unary and stream against a second daemon started with
//                          --work-threads 1 (the default is one per core)
//   floor_unary, floor_stream
//                          the same client code against animspace-transport-floor
//                          (server/transport_floor/): the daemon's gRPC server with canned answers
//                          of the same size and no work behind them, the transport's ceiling on
//                          this machine; unary at 1 and 8 threads and one stream, each measured
//                          right before the daemon row it is the floor of
//
// Served rows carry their points `encoding` (float32; see kEncodings) and `bytes_per_pose`, the
// response bytes received per pose. At the end the suite sets every served row against its floor
// row (same kind, concurrency and encoding) and prints issue #25's targets as ratios.
//
// Every served row carries the in-process time per pose measured right before and right after it
// (`in_process_us_per_pose`): this machine is shared and its speed drifts by several times within
// a minute, so each row is set against the baseline of its own moment. Rows also carry the
// soft-cache outcomes received (checked frame by frame against the in-process verdict), the CPU
// time the daemon and this client spent per pose (/proc and getrusage: on 2 cores both share the
// same CPUs) and the 1-minute load average.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <cblas.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "animspace/v1/poses.grpc.pb.h"
#include "bench/crane_split.h"
#include "clients/cpp/client.h"
#include "clients/cpp/coordinates.h"
#include "bench/suites.h"
#include "clients/cpp/tools/quantile.h"
#include "core/container/model_container.h"
#include "core/mesh_io/sequence_io.h"
#include "core/pmsc/pmsc_io.h"
#include "core/pmsc/train.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "harness/daemon_process.h"

namespace animspace::bench {
namespace {

using Clock = std::chrono::steady_clock;

constexpr const char* kModelName = kCraneModelName;
// How long each unary and in-process throughput measurement runs, after a short warm-up.
constexpr double kMeasureSeconds = 2.5;
constexpr double kWarmupSeconds = 0.3;
// Stream length: the 87 odd frames looped 40 times (≥ 1 s at the 3,000 poses/s target).
constexpr int kStreamFrames = 3480;
// The server's stream read-ahead window (server/services/key_point_stream.h, kWindow).
constexpr int kBatchPoses = 8;
// Issue #25's batch: large enough that the reconstruction is a GEMM bound by arithmetic, not by
// streaming the basis from memory once per pose.
constexpr int kGemmBatchPoses = 64;
// How long a server thread sleeps between requests in the *_after_idle baselines.
constexpr auto kIdleGap = std::chrono::milliseconds(1);

// The points encodings of the served answers (PointArray.encoding, issue #25). Every encoding gets
// its own floor (--bytes-per-value), floor rows and daemon rows, and the "vs floor" table and
// targets pair rows of the same encoding.
struct Encoding {
  const char* name;
  int bytes_per_value;
  v1::PointEncoding wire;
};
constexpr Encoding kEncodings[] = {{"float32", 4, v1::POINT_ENCODING_FLOAT32},
                                   {"float16", 2, v1::POINT_ENCODING_FLOAT16},
                                   {"fixed16", 2, v1::POINT_ENCODING_FIXED16}};
// Answers as subspace coordinates (issue #36): M values per answer, reconstructed by the client.
// No floor (the floor's canned answers are points); its rows pair with float32's.
constexpr Encoding kCoordinates{"coordinates", 0, v1::POINT_ENCODING_COORDINATES};
// Answers a coordinates row keeps to reconstruct after the measurement (client_reconstruct_us).
constexpr size_t kReconstructionSamples = 256;

// Where served rows send their calls: a daemon, or the transport floor, whose answers are canned
// (no soft-cache verdicts to check).
struct Endpoint {
  std::string address;
  pid_t pid = -1;
  bool floor = false;
};

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double load_average_1m() {
  std::ifstream in("/proc/loadavg");
  double load = 0;
  in >> load;
  return load;
}

// CPU seconds (user + system) of a process: the daemon's from /proc/<pid>/stat, ours from
// getrusage (every thread, gRPC's included). Clock-tick resolution (10 ms) is fine over seconds.
double process_cpu_seconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
  const size_t close = text.rfind(')');
  if (close == std::string::npos || close + 2 > text.size()) return 0;
  std::istringstream fields(text.substr(close + 2));
  std::string field;
  double utime = 0, stime = 0;
  for (int index = 3; index <= 15 && fields >> field; ++index) {
    if (index == 14) utime = std::stod(field);
    if (index == 15) stime = std::stod(field);
  }
  return (utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

double self_cpu_seconds() {
  rusage usage{};
  ::getrusage(RUSAGE_SELF, &usage);
  auto seconds = [](const timeval& t) { return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec); };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

// CPU spent by the daemon and by this process between construction and stop().
class CpuMeter {
 public:
  explicit CpuMeter(pid_t daemon)
      : daemon_(daemon), daemon0_(process_cpu_seconds(daemon)), self0_(self_cpu_seconds()) {}
  void stop() {
    daemon_seconds = process_cpu_seconds(daemon_) - daemon0_;
    client_seconds = self_cpu_seconds() - self0_;
  }
  double daemon_seconds = 0, client_seconds = 0;

 private:
  pid_t daemon_;
  double daemon0_, self0_;
};

// Soft-cache outcomes of the answers a measurement received, and how many disagreed with the
// in-process verdict for the same frame.
struct Outcomes {
  long hit = 0, blend = 0, miss = 0, mismatched = 0;
  void add(v1::CacheStatus status, pmsc::CacheStatus expected) {
    hit += status == v1::CACHE_STATUS_HIT ? 1 : 0;
    blend += status == v1::CACHE_STATUS_BLEND ? 1 : 0;
    miss += status == v1::CACHE_STATUS_MISS ? 1 : 0;
    const v1::CacheStatus want = expected == pmsc::CacheStatus::kHit     ? v1::CACHE_STATUS_HIT
                                 : expected == pmsc::CacheStatus::kBlend ? v1::CACHE_STATUS_BLEND
                                                                         : v1::CACHE_STATUS_MISS;
    mismatched += status == want ? 0 : 1;
  }
  void merge(const Outcomes& other) {
    hit += other.hit;
    blend += other.blend;
    miss += other.miss;
    mismatched += other.mismatched;
  }
  long total() const { return hit + blend + miss; }
};

// One measured row: what the table prints and the JSON keeps.
struct Row {
  explicit Row(std::string mode_name, int threads = 1) : mode(std::move(mode_name)), concurrency(threads) {}
  std::string mode;
  int concurrency = 1;
  std::string channels;          // unary: "shared" or "per-thread"
  std::string encoding;          // served rows with points: kEncodings' name
  long response_bytes = 0;       // served rows: response messages' bytes received while measured
  double max_error = 0;          // served rows: the largest quantisation error the answers reported
  std::optional<double> sgemm_poses_per_second;  // in_process_batch64: cblas_sgemm in the same loop
  std::optional<int> work_threads;  // served rows: the daemon's --work-threads (0 = one per core)
  long poses = 0;
  double seconds = 0;
  std::vector<double> latency_us;  // per call (unary), per frame send → result (stream), per pose
  std::optional<double> baseline_us;  // in-process µs per pose measured around this row
  Outcomes outcomes;
  std::optional<double> daemon_cpu_seconds, client_cpu_seconds;
  // Coordinates rows: the client's reconstruction of the sampled answers (µs per pose, median),
  // and the largest |reconstructed − in-process float32| value over them.
  std::optional<double> client_reconstruct_us, client_reconstruct_max_difference;
  std::vector<std::pair<size_t, v1::PoseResult>> samples;  // (frame, answer), coordinates rows only
  double load_average = 0;
  std::string error;  // first failure, if any
  bool in_order = true;
};

// The served model's inputs: the odd frames' key values packed as the wire expects, with the
// in-process verdict and points of each.
struct Workload {
  int point_count = 0;  // N
  int key_count = 0;    // K
  int basis_size = 0;   // M
  std::vector<Eigen::VectorXf> keys;
  std::vector<std::string> packed_keys;  // K·3 little-endian float32
  std::vector<pmsc::CacheStatus> expected;
  std::vector<Eigen::VectorXf> expected_points;
  double diagonal = 0;  // of the in-process answers' bounding box: the scale of quantisation errors
};

std::string pack_floats(const Eigen::VectorXf& values) {
  static_assert(std::endian::native == std::endian::little, "PointArray.data is little-endian float32");
  return std::string(reinterpret_cast<const char*>(values.data()), sizeof(float) * static_cast<size_t>(values.size()));
}

v1::PointArray point_array(const std::string& packed, int points) {
  v1::PointArray array;
  array.set_point_count(static_cast<uint32_t>(points));
  array.set_channel_count(3);
  array.set_data(packed);
  return array;
}

// ---------------------------------------------------------------------------------------------
// In process

// Each odd frame `passes` times, one pose after another (or after `idle` asleep), µs per pose.
enum class Gap { kNone, kSleep, kSpin };

// Each odd frame `passes` times, one pose after another, or after kIdleGap asleep or busy-waiting;
// µs per pose.
std::vector<double> evaluate_poses(const pmsc::PmscModel& model, const Workload& work, int passes,
                                   Gap gap = Gap::kNone) {
  std::vector<double> samples;
  pmsc::CachedPose cached;
  for (int pass = 0; pass < passes; ++pass) {
    for (const Eigen::VectorXf& keys : work.keys) {
      if (gap == Gap::kSleep) std::this_thread::sleep_for(kIdleGap);
      if (gap == Gap::kSpin) {
        for (const auto until = Clock::now() + kIdleGap; Clock::now() < until;) {
        }
      }
      const auto start = Clock::now();
      pmsc::evaluate_cached(model, keys, nullptr, cached);
      do_not_optimize(cached.points.data());
      samples.push_back(1e6 * seconds_since(start));
    }
  }
  return samples;
}

Row measure_in_process(const pmsc::PmscModel& model, const Workload& work, int passes, Gap gap) {
  Row row(gap == Gap::kSleep ? "in_process_after_idle" : gap == Gap::kSpin ? "in_process_after_spin" : "in_process");
  // Warm up for a while: right after training the process is still returning memory to the OS.
  for (const auto t0 = Clock::now(); seconds_since(t0) < kWarmupSeconds;) evaluate_poses(model, work, 1);
  const auto t0 = Clock::now();
  row.latency_us = evaluate_poses(model, work, passes, gap);
  row.seconds = seconds_since(t0);
  // With gaps: throughput from the evaluation time alone, the gaps excluded.
  if (gap != Gap::kNone) row.seconds = std::accumulate(row.latency_us.begin(), row.latency_us.end(), 0.0) * 1e-6;
  row.poses = static_cast<long>(row.latency_us.size());
  return row;
}

// `threads` threads evaluating poses one by one for kMeasureSeconds: the machine's ceiling for a
// server without batching.
Row measure_in_process_parallel(const pmsc::PmscModel& model, const Workload& work, int threads) {
  Row row("in_process", threads);
  std::vector<std::vector<double>> samples(static_cast<size_t>(threads));
  const auto t0 = Clock::now();
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) {
    pool.emplace_back([&, t] {
      pmsc::CachedPose cached;
      for (size_t f = static_cast<size_t>(t) * 40; seconds_since(t0) < kMeasureSeconds; ++f) {
        const auto start = Clock::now();
        pmsc::evaluate_cached(model, work.keys[f % work.keys.size()], nullptr, cached);
        do_not_optimize(cached.points.data());
        samples[static_cast<size_t>(t)].push_back(1e6 * seconds_since(start));
      }
    });
  }
  for (auto& thread : pool) thread.join();
  row.seconds = seconds_since(t0);
  for (const auto& s : samples) row.latency_us.insert(row.latency_us.end(), s.begin(), s.end());
  row.poses = static_cast<long>(row.latency_us.size());
  return row;
}

// evaluate_batch on `batch_poses` poses at a time; latency_us holds µs per pose of each batch. With
// `with_sgemm`, each batch is followed by cblas_sgemm on the reconstruction it contains (the float
// basis times the batch's coordinates, computed beforehand), timed alone: the same product at
// OpenBLAS's speed, in the same moments.
Row measure_in_process_batch(const pmsc::PmscModel& model, const Workload& work, int batch_poses, int batches,
                             bool after_idle, bool with_sgemm) {
  Row row(std::string("in_process_batch") + (batch_poses == kBatchPoses ? "" : std::to_string(batch_poses)) +
          (after_idle ? "_after_idle" : ""));
  Eigen::MatrixXf keys(work.keys.front().size(), batch_poses);
  Eigen::MatrixXf points;
  Eigen::VectorXd errors;
  Eigen::MatrixXf coordinates, gemm_points(model.basis.rows(), batch_poses);
  double sgemm_seconds = 0;
  for (int batch = -1; batch < batches; ++batch) {  // batch −1 warms up
    for (long b = 0; b < batch_poses; ++b) {
      keys.col(b) = work.keys[static_cast<size_t>((batch + 1) * batch_poses + b) % work.keys.size()];
    }
    if (after_idle) std::this_thread::sleep_for(kIdleGap);
    auto start = Clock::now();
    pmsc::evaluate_batch(model, keys, points, errors);
    do_not_optimize(points.data());
    if (batch >= 0) row.latency_us.push_back(1e6 * seconds_since(start) / batch_poses);
    if (!with_sgemm) continue;
    // p = P (f_key − mean_key), as evaluate_batch projects an unaligned model's keys.
    coordinates = (model.projection * (keys.cast<double>().colwise() - model.key_mean)).cast<float>();
    start = Clock::now();
    cblas_sgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, static_cast<int>(model.basis.rows()), batch_poses,
                static_cast<int>(model.basis.cols()), 1.0f, model.basis.data(), static_cast<int>(model.basis.rows()),
                coordinates.data(), static_cast<int>(coordinates.rows()), 0.0f, gemm_points.data(),
                static_cast<int>(gemm_points.rows()));
    do_not_optimize(gemm_points.data());
    if (batch >= 0) sgemm_seconds += seconds_since(start);
  }
  row.poses = static_cast<long>(row.latency_us.size()) * batch_poses;
  // Throughput from the evaluation time alone (the idle gaps and key copies excluded).
  row.seconds = std::accumulate(row.latency_us.begin(), row.latency_us.end(), 0.0) * batch_poses * 1e-6;
  if (with_sgemm && sgemm_seconds > 0) row.sgemm_poses_per_second = static_cast<double>(row.poses) / sgemm_seconds;
  return row;
}

// The protobuf share of one answer, in process: building a response with N·D points the way the
// server does (one copy into the bytes field) and serialising it; then parsing it back.
std::pair<Row, Row> measure_protobuf(const Workload& work, int repetitions) {
  Row encode("encode_response"), decode("decode_response");
  std::string wire;
  for (int r = 0; r < repetitions; ++r) {
    const Eigen::VectorXf& points = work.expected_points[static_cast<size_t>(r) % work.expected_points.size()];
    auto start = Clock::now();
    v1::EvaluateKeyPointsResponse response;
    v1::PoseResult* result = response.add_results();
    result->set_status(v1::CACHE_STATUS_HIT);
    result->set_model_version(1);
    result->mutable_points()->set_point_count(static_cast<uint32_t>(work.point_count));
    result->mutable_points()->set_channel_count(3);
    result->mutable_points()->set_data(points.data(), sizeof(float) * static_cast<size_t>(points.size()));
    wire.clear();
    response.SerializeToString(&wire);
    encode.latency_us.push_back(1e6 * seconds_since(start));

    start = Clock::now();
    v1::EvaluateKeyPointsResponse parsed;
    parsed.ParseFromString(wire);
    do_not_optimize(parsed.results(0).points().data().data());
    decode.latency_us.push_back(1e6 * seconds_since(start));
  }
  encode.poses = decode.poses = static_cast<long>(encode.latency_us.size());
  encode.seconds = std::accumulate(encode.latency_us.begin(), encode.latency_us.end(), 0.0) * 1e-6;
  decode.seconds = std::accumulate(decode.latency_us.begin(), decode.latency_us.end(), 0.0) * 1e-6;
  return {encode, decode};
}

// ---------------------------------------------------------------------------------------------
// Over gRPC

std::shared_ptr<grpc::Channel> make_channel(const std::string& address, bool own_connection) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  // Channels with equal arguments share one subchannel (one TCP connection) through gRPC's global
  // pool; a local pool gives each channel its own connection.
  if (own_connection) args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
}

// Waits for health SERVING (the repository is loaded), then checks that the daemon serves the
// key points we trained. Returns a problem, or "".
std::string wait_for_model(const std::string& address, const pmsc::PmscModel& model) {
  const auto channel = make_channel(address, false);
  auto health = grpc::health::v1::Health::NewStub(channel);
  const auto deadline = Clock::now() + std::chrono::seconds(60);
  for (;;) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
    grpc::health::v1::HealthCheckResponse response;
    const grpc::Status status = health->Check(&context, grpc::health::v1::HealthCheckRequest{}, &response);
    if (status.ok() && response.status() == grpc::health::v1::HealthCheckResponse::SERVING) break;
    if (Clock::now() > deadline) return "the daemon never reported SERVING";
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  auto poses = v1::PoseService::NewStub(channel);
  grpc::ClientContext context;
  v1::DescribeKeyPointsRequest request;
  request.mutable_model()->set_name(kModelName);
  v1::DescribeKeyPointsResponse response;
  if (const grpc::Status status = poses->DescribeKeyPoints(&context, request, &response); !status.ok()) {
    return "DescribeKeyPoints: " + status.error_message();
  }
  if (response.key_point_indices_size() != model.key_point_count()) return "the daemon serves a different key set";
  for (int k = 0; k < model.key_point_count(); ++k) {
    if (static_cast<int>(response.key_point_indices(k)) != model.key_points[static_cast<size_t>(k)]) {
      return "the daemon's key point " + std::to_string(k) + " differs from the trained model's";
    }
  }
  return "";
}

// One EvaluateKeyPoints request per odd frame, one pose each.
std::vector<v1::EvaluateKeyPointsRequest> unary_requests(const Workload& work, bool omit_points,
                                                         v1::PointEncoding encoding = v1::POINT_ENCODING_FLOAT32) {
  std::vector<v1::EvaluateKeyPointsRequest> requests(work.packed_keys.size());
  for (size_t f = 0; f < requests.size(); ++f) {
    requests[f].mutable_model()->set_name(kModelName);
    *requests[f].add_poses()->mutable_key_values() = point_array(work.packed_keys[f], work.key_count);
    requests[f].set_omit_points(omit_points);
    requests[f].set_points_encoding(encoding);
  }
  return requests;
}

// Compares every served answer with the in-process points for the same frame: the rows measure
// the same work only if the daemon computes what pmsc::evaluate_cached computes.
std::string check_points(const std::string& address, const Workload& work, double* max_difference) {
  auto stub = v1::PoseService::NewStub(make_channel(address, false));
  const auto requests = unary_requests(work, false);
  *max_difference = 0;
  for (size_t f = 0; f < requests.size(); ++f) {
    grpc::ClientContext context;
    v1::EvaluateKeyPointsResponse response;
    const grpc::Status status = stub->EvaluateKeyPoints(&context, requests[f], &response);
    if (!status.ok()) return "EvaluateKeyPoints: " + status.error_message();
    const std::string& data = response.results(0).points().data();
    if (data.size() != sizeof(float) * static_cast<size_t>(work.expected_points[f].size())) return "wrong point count";
    Eigen::VectorXf served(work.expected_points[f].size());
    std::memcpy(served.data(), data.data(), data.size());
    *max_difference =
        std::max(*max_difference, static_cast<double>((served - work.expected_points[f]).cwiseAbs().maxCoeff()));
  }
  return "";
}

// Bytes of points in each answer.
size_t point_bytes(const Workload& work, const Encoding& encoding, bool omit_points) {
  return omit_points ? 0 : static_cast<size_t>(encoding.bytes_per_value) * 3 * static_cast<size_t>(work.point_count);
}

// Whether `result` is an answer of the row's shape: `expected_bytes` of points, or — coordinates —
// M coordinates and no points (crane's model has no server engine: every answer is the client's).
bool answer_shape_ok(const v1::PoseResult& result, const Encoding& encoding, size_t expected_bytes,
                     const Workload& work) {
  if (encoding.wire == v1::POINT_ENCODING_COORDINATES) {
    return result.coordinates().p_size() == work.basis_size && result.points().data().empty();
  }
  return result.points().data().size() == expected_bytes;
}

// `concurrency` threads, each with its own stub (on one shared channel or on its own), calling
// EvaluateKeyPoints back to back for kMeasureSeconds after a warm-up.
Row measure_unary(const Endpoint& server, const Workload& work, const Encoding& encoding, int concurrency,
                  bool channel_per_thread, bool omit_points) {
  Row row(std::string(server.floor ? "floor_" : "") + (omit_points ? "unary_omit_points" : "unary"), concurrency);
  row.channels = channel_per_thread ? "per-thread" : "shared";
  row.encoding = encoding.name;
  const std::string& address = server.address;
  const auto requests = unary_requests(work, omit_points, encoding.wire);
  const auto shared = make_channel(address, false);
  const size_t expected_bytes = point_bytes(work, encoding, omit_points);

  struct Worker {
    std::vector<double> latency_us;
    Outcomes outcomes;
    long response_bytes = 0;
    double max_error = 0;  // largest PointArray.max_error received (16-bit encodings)
    std::vector<std::pair<size_t, v1::PoseResult>> samples;
    std::string error;
  };
  std::vector<Worker> workers(static_cast<size_t>(concurrency));
  std::atomic<int> ready{0};
  std::atomic<bool> go{false};
  Clock::time_point measure_end;

  auto body = [&](int t) {
    Worker& me = workers[static_cast<size_t>(t)];
    const auto stub = v1::PoseService::NewStub(channel_per_thread ? make_channel(address, true) : shared);
    v1::EvaluateKeyPointsResponse response;
    auto call = [&](size_t frame) -> bool {
      grpc::ClientContext context;
      context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
      response.Clear();
      const grpc::Status status = stub->EvaluateKeyPoints(&context, requests[frame], &response);
      if (!status.ok()) {
        me.error = "EvaluateKeyPoints: " + std::to_string(status.error_code()) + " " + status.error_message();
        return false;
      }
      if (response.results_size() != 1 || !answer_shape_ok(response.results(0), encoding, expected_bytes, work)) {
        me.error = "EvaluateKeyPoints: unexpected response shape";
        return false;
      }
      return true;
    };
    // Warm-up: connects, and lets HTTP/2 flow control grow its windows.
    size_t next = static_cast<size_t>(t) * 7;
    const auto warm_until = Clock::now() + std::chrono::duration<double>(kWarmupSeconds);
    while (Clock::now() < warm_until && call(next++ % requests.size())) {
    }
    ++ready;
    while (!go.load()) std::this_thread::yield();
    while (me.error.empty() && Clock::now() < measure_end) {
      const size_t frame = next++ % requests.size();
      const auto start = Clock::now();
      if (!call(frame)) break;
      me.latency_us.push_back(1e6 * seconds_since(start));
      me.response_bytes += static_cast<long>(response.ByteSizeLong());
      if (!server.floor) me.outcomes.add(response.results(0).status(), work.expected[frame]);
      me.max_error = std::max(me.max_error, static_cast<double>(response.results(0).points().max_error()));
      if (response.results(0).has_coordinates() && me.samples.size() < kReconstructionSamples / 8 + 1) {
        me.samples.emplace_back(frame, response.results(0));
      }
    }
  };

  std::vector<std::thread> threads;
  for (int t = 0; t < concurrency; ++t) threads.emplace_back(body, t);
  while (ready.load() < concurrency) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  CpuMeter cpu(server.pid);
  const auto measure_start = Clock::now();
  measure_end =
      measure_start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(kMeasureSeconds));
  go = true;
  for (auto& thread : threads) thread.join();
  row.seconds = seconds_since(measure_start);
  cpu.stop();
  row.daemon_cpu_seconds = cpu.daemon_seconds;
  row.client_cpu_seconds = cpu.client_seconds;
  for (const Worker& w : workers) {
    row.latency_us.insert(row.latency_us.end(), w.latency_us.begin(), w.latency_us.end());
    row.outcomes.merge(w.outcomes);
    row.response_bytes += w.response_bytes;
    row.max_error = std::max(row.max_error, w.max_error);
    row.samples.insert(row.samples.end(), w.samples.begin(), w.samples.end());
    if (row.error.empty()) row.error = w.error;
  }
  row.poses = static_cast<long>(row.latency_us.size());
  return row;
}

// DescribeKeyPoints back to back from one thread: a unary round trip through the same admission
// and work-pool hop as EvaluateKeyPoints, with no evaluation and a 1 KB answer — the floor under
// every unary call on this machine.
Row measure_round_trip(const std::string& address, pid_t daemon) {
  Row row("describe_key_points");
  auto stub = v1::PoseService::NewStub(make_channel(address, false));
  v1::DescribeKeyPointsRequest request;
  request.mutable_model()->set_name(kModelName);
  long response_bytes = 0;
  auto call = [&]() -> bool {
    grpc::ClientContext context;
    v1::DescribeKeyPointsResponse response;
    const grpc::Status status = stub->DescribeKeyPoints(&context, request, &response);
    if (!status.ok()) row.error = "DescribeKeyPoints: " + status.error_message();
    response_bytes += static_cast<long>(response.ByteSizeLong());
    return status.ok();
  };
  for (const auto warm_until = Clock::now() + std::chrono::duration<double>(kWarmupSeconds);
       Clock::now() < warm_until && call();) {
  }
  response_bytes = 0;
  CpuMeter cpu(daemon);
  const auto t0 = Clock::now();
  while (row.error.empty() && seconds_since(t0) < kMeasureSeconds / 2) {
    const auto start = Clock::now();
    if (call()) row.latency_us.push_back(1e6 * seconds_since(start));
  }
  row.seconds = seconds_since(t0);
  cpu.stop();
  row.daemon_cpu_seconds = cpu.daemon_seconds;
  row.client_cpu_seconds = cpu.client_seconds;
  row.poses = static_cast<long>(row.latency_us.size());
  row.response_bytes = response_bytes;
  return row;
}

// `streams` StreamKeyPoints calls at once, each replaying kStreamFrames frames (the odd frames
// looped) from a writer thread while its reader checks that results arrive in order. The writer
// never waits for results, so the latency of a frame includes every frame queued ahead of it.
Row measure_stream(const Endpoint& server, const Workload& work, const Encoding& encoding, int streams,
                   bool omit_points) {
  Row row(std::string(server.floor ? "floor_" : "") + (omit_points ? "stream_omit_points" : "stream"), streams);
  row.encoding = encoding.name;
  const size_t expected_bytes = point_bytes(work, encoding, omit_points);
  std::vector<v1::KeyPointFrame> frames(work.packed_keys.size());
  for (size_t f = 0; f < frames.size(); ++f) {
    *frames[f].mutable_pose()->mutable_key_values() = point_array(work.packed_keys[f], work.key_count);
    frames[f].set_omit_points(omit_points);
    frames[f].set_points_encoding(encoding.wire);
  }
  const auto channel = make_channel(server.address, false);

  struct StreamState {
    std::unique_ptr<v1::PoseService::Stub> stub;
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReaderWriter<v1::KeyPointFrame, v1::PoseResult>> call;
    std::vector<std::atomic<int64_t>> sent_ns = std::vector<std::atomic<int64_t>>(kStreamFrames);
    std::vector<double> latency_us;
    Outcomes outcomes;
    bool in_order = true;
    long received = 0;
    long response_bytes = 0;
    double max_error = 0;
    std::vector<std::pair<size_t, v1::PoseResult>> samples;
    std::string error;
  };
  std::vector<std::unique_ptr<StreamState>> states;
  for (int s = 0; s < streams; ++s) {
    auto state = std::make_unique<StreamState>();
    state->stub = v1::PoseService::NewStub(channel);
    state->call = state->stub->StreamKeyPoints(&state->context);
    states.push_back(std::move(state));
  }

  CpuMeter cpu(server.pid);
  const auto t0 = Clock::now();
  auto now_ns = [&] { return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t0).count(); };
  std::vector<std::thread> threads;
  for (auto& owned : states) {
    StreamState* state = owned.get();
    threads.emplace_back([&, state] {
      for (int i = 0; i < kStreamFrames; ++i) {
        v1::KeyPointFrame frame = frames[static_cast<size_t>(i) % frames.size()];
        frame.set_sequence(static_cast<uint64_t>(i));
        if (i == 0) frame.mutable_model()->set_name(kModelName);
        state->sent_ns[static_cast<size_t>(i)].store(now_ns(), std::memory_order_release);
        if (!state->call->Write(frame)) break;
      }
      state->call->WritesDone();
    });
    threads.emplace_back([&, state] {
      v1::PoseResult result;
      while (state->call->Read(&result)) {
        const auto expected_sequence = static_cast<uint64_t>(state->received);
        if (result.sequence() != expected_sequence) state->in_order = false;
        if (!answer_shape_ok(result, encoding, expected_bytes, work) && state->error.empty()) {
          state->error = "stream: unexpected result shape";
        }
        const size_t index = static_cast<size_t>(result.sequence() % static_cast<uint64_t>(kStreamFrames));
        state->latency_us.push_back(
            1e-3 * static_cast<double>(now_ns() - state->sent_ns[index].load(std::memory_order_acquire)));
        if (!server.floor) state->outcomes.add(result.status(), work.expected[index % work.expected.size()]);
        state->response_bytes += static_cast<long>(result.ByteSizeLong());
        state->max_error = std::max(state->max_error, static_cast<double>(result.points().max_error()));
        if (result.has_coordinates() && state->samples.size() < kReconstructionSamples) {
          state->samples.emplace_back(index % work.expected.size(), result);
        }
        ++state->received;
      }
    });
  }
  for (auto& thread : threads) thread.join();
  row.seconds = seconds_since(t0);
  cpu.stop();
  row.daemon_cpu_seconds = cpu.daemon_seconds;
  row.client_cpu_seconds = cpu.client_seconds;
  for (auto& state : states) {
    const grpc::Status status = state->call->Finish();
    if (!status.ok() && state->error.empty()) {
      state->error = "StreamKeyPoints: " + std::to_string(status.error_code()) + " " + status.error_message();
    }
    if (state->received != kStreamFrames && state->error.empty()) {
      state->error = "stream: " + std::to_string(state->received) + " of " + std::to_string(kStreamFrames) + " results";
    }
    row.latency_us.insert(row.latency_us.end(), state->latency_us.begin(), state->latency_us.end());
    row.outcomes.merge(state->outcomes);
    row.in_order = row.in_order && state->in_order;
    if (row.error.empty()) row.error = state->error;
    row.poses += state->received;
    row.response_bytes += state->response_bytes;
    row.max_error = std::max(row.max_error, state->max_error);
    row.samples.insert(row.samples.end(), state->samples.begin(), state->samples.end());
  }
  return row;
}

// The client's half of a coordinates row, measured after it: the basis fetched once (GetBasis),
// then every sampled answer reconstructed as the C++ client does (clients/cpp/coordinates.h),
// timed one by one and compared with the in-process float32 answer of its frame.
void reconstruct_samples(const std::string& address, const Workload& work, Row& row) {
  if (row.samples.empty()) return;
  try {
    Client client(address);
    const Basis basis = make_basis(std::string(kModelName), client.get_basis(std::string(kModelName)));
    std::vector<double> us;
    double max_difference = 0;
    Points points;
    for (const auto& [frame, answer] : row.samples) {
      const PoseResult result = decode_pose_result(answer);
      const auto start = Clock::now();
      reconstruct(basis, result, points);
      us.push_back(1e6 * seconds_since(start));
      const Eigen::VectorXf& expected = work.expected_points[frame];
      const Eigen::Map<const Eigen::VectorXf> got(points.values.data(), static_cast<long>(points.values.size()));
      if (got.size() != expected.size()) {
        row.error = "client reconstruction: " + std::to_string(got.size()) + " values, expected " +
                    std::to_string(expected.size());
        return;
      }
      max_difference = std::max(max_difference, static_cast<double>((got - expected).cwiseAbs().maxCoeff()));
    }
    row.client_reconstruct_us = tools::quantile(us, 0.5);
    row.client_reconstruct_max_difference = max_difference;
  } catch (const std::exception& e) {
    row.error = std::string("client reconstruction: ") + e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Reporting

void print_header() {
  std::printf("%-27s %4s %-10s %-7s %7s %9s %9s %9s %8s %6s %6s %6s %6s %4s %5s\n", "mode", "conc", "variant", "enc",
              "B/pose", "poses/s", "p50 us", "p99 us", "base us", "dcpu/b", "d cpu", "c cpu", "hit", "mism", "load");
}

void report(const Row& row, double run_baseline_us, std::vector<nlohmann::json>& out) {
  const double pps = row.seconds > 0 ? static_cast<double>(row.poses) / row.seconds : 0;
  const double p50 = tools::quantile(row.latency_us, 0.50), p99 = tools::quantile(row.latency_us, 0.99);
  const double baseline = row.baseline_us.value_or(run_baseline_us);
  nlohmann::json json = {
      {"mode", row.mode},
      {"concurrency", row.concurrency},
      {"poses_per_second", pps},
      {"p50_us", p50},
      {"p99_us", p99},
      {"in_process_us_per_pose", baseline},
      {"in_process_us_per_pose_run", run_baseline_us},
      {"poses", row.poses},
      {"seconds", row.seconds},
      {"load_average_1m", row.load_average},
  };
  std::string variant = row.channels;
  if (!row.channels.empty()) json["channels"] = row.channels;
  if (row.work_threads) {
    json["work_threads"] = *row.work_threads;
    if (*row.work_threads > 0) {
      variant = "wt=" + std::to_string(*row.work_threads) + (variant.empty() ? "" : " ") + variant;
    }
  }
  if (!row.encoding.empty()) json["encoding"] = row.encoding;
  if (row.max_error > 0) json["max_quantization_error"] = row.max_error;
  char bytes_per_pose[16] = "-";
  if (row.response_bytes > 0 && row.poses > 0) {
    json["bytes_per_pose"] = static_cast<double>(row.response_bytes) / static_cast<double>(row.poses);
    std::snprintf(bytes_per_pose, sizeof bytes_per_pose, "%.0f", json["bytes_per_pose"].get<double>());
  }
  if (row.sgemm_poses_per_second) json["openblas_sgemm_poses_per_second"] = *row.sgemm_poses_per_second;
  if (row.client_reconstruct_us) {
    json["client_reconstruct_us"] = *row.client_reconstruct_us;
    json["client_reconstruct_max_difference"] = *row.client_reconstruct_max_difference;
    json["client_reconstruct_samples"] = row.samples.size();
  }
  const long total = row.outcomes.total();
  char hit[16] = "-", mismatched[16] = "-";
  if (total > 0) {
    const double hit_rate = static_cast<double>(row.outcomes.hit) / static_cast<double>(total);
    json["hit_rate"] = hit_rate;
    json["hits"] = row.outcomes.hit;
    json["blends"] = row.outcomes.blend;
    json["misses"] = row.outcomes.miss;
    json["status_mismatches"] = row.outcomes.mismatched;
    std::snprintf(hit, sizeof hit, "%.3f", hit_rate);
    std::snprintf(mismatched, sizeof mismatched, "%ld", row.outcomes.mismatched);
  }
  const bool stream = row.mode.starts_with("stream") || row.mode.starts_with("floor_stream");
  if (stream) json["in_order"] = row.in_order;
  char daemon_cpu[16] = "-", client_cpu[16] = "-", daemon_ratio[16] = "-";
  if (row.daemon_cpu_seconds && row.poses > 0) {
    const double daemon_us = 1e6 * *row.daemon_cpu_seconds / static_cast<double>(row.poses);
    const double client_us = 1e6 * *row.client_cpu_seconds / static_cast<double>(row.poses);
    json["daemon_cpu_us_per_pose"] = daemon_us;
    json["client_cpu_us_per_pose"] = client_us;
    std::snprintf(daemon_cpu, sizeof daemon_cpu, "%.0f", daemon_us);
    std::snprintf(client_cpu, sizeof client_cpu, "%.0f", client_us);
    std::snprintf(daemon_ratio, sizeof daemon_ratio, "%.2f", daemon_us / baseline);
  }
  if (!row.error.empty()) json["error"] = row.error;
  if (stream && !row.in_order && row.error.empty()) json["error"] = "results out of order";
  const std::string error = json.contains("error") ? " ERROR " + json["error"].get<std::string>() : "";
  std::printf("%-27s %4d %-10s %-7s %7s %9.0f %9.1f %9.1f %8.1f %6s %6s %6s %6s %4s %5.1f%s\n", row.mode.c_str(),
              row.concurrency, variant.empty() ? "-" : variant.c_str(),
              row.encoding.empty() ? "-" : row.encoding.c_str(), bytes_per_pose, pps, p50, p99, baseline, daemon_ratio, daemon_cpu, client_cpu, hit, mismatched,
              row.load_average, error.c_str());
  if (row.client_reconstruct_us) {
    std::printf("  client reconstruction of %zu sampled answers: %.1f us per pose (median); largest difference from "
                "the in-process float32 answer %.3g\n",
                row.samples.size(), *row.client_reconstruct_us, *row.client_reconstruct_max_difference);
  }
  if (row.sgemm_poses_per_second) {
    std::printf("  openblas cblas_sgemm on the same products (N·D × M times M × %d): %.0f poses/s; this row / sgemm "
                "= %.2f\n",
                kGemmBatchPoses, *row.sgemm_poses_per_second, pps / *row.sgemm_poses_per_second);
  }
  std::fflush(stdout);
  out.push_back(json);
}

// Starts a daemon on `repository`, waits until it serves the model and checks its answers.
std::unique_ptr<harness::DaemonProcess> start_daemon(const ScratchDirectory& scratch,
                                                     const std::filesystem::path& repository, int work_threads,
                                                     const pmsc::PmscModel& model, const Workload& work) {
  std::unique_ptr<harness::DaemonProcess> daemon;
  try {
    daemon = std::make_unique<harness::DaemonProcess>(
        std::vector<std::string>{"--model-repository", repository.string(), "--log-level", "warn", "--miss-log-fsync",
                                 "never", "--work-threads", std::to_string(work_threads)},
        scratch.path());
  } catch (const std::exception& e) {
    std::printf("serve: the daemon did not start: %s\n", e.what());
    return nullptr;
  }
  if (const std::string problem = wait_for_model(daemon->address(), model); !problem.empty()) {
    std::printf("serve: %s\n%s\n", problem.c_str(), daemon->log().c_str());
    return nullptr;
  }
  double max_difference = 0;
  if (const std::string problem = check_points(daemon->address(), work, &max_difference); !problem.empty()) {
    std::printf("serve: %s\n", problem.c_str());
    return nullptr;
  }
  if (max_difference != 0) {
    std::printf("serve: note: served points differ from the in-process ones by up to %g\n", max_difference);
  }
  return daemon;
}

// Starts animspace-transport-floor answering as the daemon would for `work`'s model in `encoding`,
// in a folder of its own (its log and port file). Null, with the reason printed, when it does not
// start: the daemon rows are still measured, without their floor.
std::unique_ptr<harness::DaemonProcess> start_floor(const ScratchDirectory& scratch, const Workload& work,
                                                    const Encoding& encoding) {
  const auto folder = scratch.path() / (std::string("floor-") + encoding.name);
  try {
    std::filesystem::create_directories(folder);
    return std::make_unique<harness::DaemonProcess>(
        harness::transport_floor_binary(),
        std::vector<std::string>{"--point-count", std::to_string(work.point_count), "--channel-count", "3",
                                 "--bytes-per-value", std::to_string(encoding.bytes_per_value)},
        folder);
  } catch (const std::exception& e) {
    std::printf("serve: the transport floor did not start (no floor rows): %s\n", e.what());
    return nullptr;
  }
}

// A JSON row of `rows` with this mode, concurrency and encoding, from the default daemon (no
// --work-threads 1) on one shared channel; null when there is none.
const nlohmann::json* find_row(const std::vector<nlohmann::json>& rows, const std::string& mode, int concurrency,
                               const std::string& encoding = "") {
  for (const nlohmann::json& row : rows) {
    if (row.value("mode", "") == mode && row.value("concurrency", 0) == concurrency &&
        row.value("encoding", "") == encoding && row.value("work_threads", 0) == 0 &&
        row.value("channels", "shared") == "shared") {
      return &row;
    }
  }
  return nullptr;
}

// Sets every unary and stream row against the floor row of the same kind, concurrency and
// encoding (the floor's is measured on a shared channel): prints the ratios and adds them to the
// row's JSON (floor_poses_per_second_ratio, floor_daemon_cpu_excess_us_per_pose; unary rows also
// floor_p50_excess_us, p50 minus the floor's, and floor_p50_excess_per_in_process_pose, that
// excess over the row's in-process µs per pose). A stream's p50 is mostly the queue its writer
// builds ahead of the server, so its excess over the floor's says nothing about the work per pose.
void compare_with_floors(std::vector<nlohmann::json>& rows) {
  std::printf("\nvs floor (same kind, concurrency and encoding against animspace-transport-floor):\n");
  // ASCII column names: printf pads by bytes.
  std::printf("%-27s %4s %-10s %-7s %11s %13s %14s %13s\n", "mode", "conc", "variant", "enc", "pps/floor",
              "p50-floor us", "(p50-fl)/base", "dcpu-floor");
  for (nlohmann::json& row : rows) {
    const std::string mode = row.value("mode", "");
    if ((mode != "unary" && mode != "stream") || row.value("channels", "shared") != "shared") continue;
    const std::string encoding = row.value("encoding", "");
    const nlohmann::json* floor = find_row(rows, "floor_" + mode, row.value("concurrency", 0), encoding);
    if (!floor || floor->value("poses_per_second", 0.0) <= 0) continue;
    const double ratio = row.value("poses_per_second", 0.0) / floor->value("poses_per_second", 0.0);
    row["floor_poses_per_second_ratio"] = ratio;
    char excess[16] = "-", excess_per_base[16] = "-";
    if (mode == "unary") {
      const double excess_us = row.value("p50_us", 0.0) - floor->value("p50_us", 0.0);
      const double base = row.value("in_process_us_per_pose", 0.0);
      row["floor_p50_excess_us"] = excess_us;
      std::snprintf(excess, sizeof excess, "%.1f", excess_us);
      if (base > 0) {
        row["floor_p50_excess_per_in_process_pose"] = excess_us / base;
        std::snprintf(excess_per_base, sizeof excess_per_base, "%.2f", excess_us / base);
      }
    }
    char cpu[16] = "-";
    if (row.contains("daemon_cpu_us_per_pose") && floor->contains("daemon_cpu_us_per_pose")) {
      const double excess_cpu =
          row["daemon_cpu_us_per_pose"].get<double>() - (*floor)["daemon_cpu_us_per_pose"].get<double>();
      row["floor_daemon_cpu_excess_us_per_pose"] = excess_cpu;
      std::snprintf(cpu, sizeof cpu, "%.0f", excess_cpu);
    }
    const int work_threads = row.value("work_threads", 0);
    const std::string variant = work_threads > 0 ? "wt=" + std::to_string(work_threads) : "-";
    std::printf("%-27s %4d %-10s %-7s %11.2f %13s %14s %13s\n", mode.c_str(), row.value("concurrency", 0),
                variant.c_str(), encoding.c_str(), ratio, excess, excess_per_base, cpu);
  }
}

// Issue #25's targets, read off the rows of this run (each against its own floor or baseline):
// printed, and returned as the JSON row {"mode": "targets", "targets": [...]}.
nlohmann::json print_targets(const std::vector<nlohmann::json>& rows, double diagonal) {
  struct Target {
    std::string name, encoding;
    std::optional<double> measured;  // none when a row it needs is missing (e.g. the floor did not start)
    double limit;
    bool at_most;  // measured ≤ limit is met; else measured ≥ limit
    bool reported_only = false;  // a figure the issue asks to report, without a limit
  };
  // (a[a_key] − b[b_key] when b is given) / c[c_key]; none when a row is missing or c is not positive.
  auto ratio = [](const nlohmann::json* a, const char* a_key, const nlohmann::json* b, const char* b_key,
                  const nlohmann::json* c, const char* c_key) -> std::optional<double> {
    if (!a || !c || (b_key && !b) || !a->contains(a_key) || (b_key && !b->contains(b_key)) || !c->contains(c_key) ||
        (*c)[c_key].get<double>() <= 0) {
      return std::nullopt;
    }
    const double minus = b_key ? (*b)[b_key].get<double>() : 0.0;
    return ((*a)[a_key].get<double>() - minus) / (*c)[c_key].get<double>();
  };
  // Names in ASCII: printf pads by bytes.
  std::vector<Target> targets;
  for (const Encoding& encoding : kEncodings) {
    const nlohmann::json* stream = find_row(rows, "stream", 1, encoding.name);
    const nlohmann::json* floor_stream = find_row(rows, "floor_stream", 1, encoding.name);
    const nlohmann::json* unary1 = find_row(rows, "unary", 1, encoding.name);
    const nlohmann::json* floor_unary1 = find_row(rows, "floor_unary", 1, encoding.name);
    const nlohmann::json* unary8 = find_row(rows, "unary", 8, encoding.name);
    const nlohmann::json* floor_unary8 = find_row(rows, "floor_unary", 8, encoding.name);
    targets.push_back({"daemon CPU per streamed pose / in-process pose", encoding.name,
                       ratio(stream, "daemon_cpu_us_per_pose", nullptr, nullptr, stream, "in_process_us_per_pose"),
                       1.3, true});
    targets.push_back({"daemon CPU per unary pose (1 caller) / in-process pose", encoding.name,
                       ratio(unary1, "daemon_cpu_us_per_pose", nullptr, nullptr, unary1, "in_process_us_per_pose"),
                       1.6, true});
    targets.push_back({"1 stream poses/s / floor_stream poses/s", encoding.name,
                       ratio(stream, "poses_per_second", nullptr, nullptr, floor_stream, "poses_per_second"), 0.8,
                       false});
    targets.push_back({"(unary c1 p50 - floor_unary c1 p50) / in-process pose", encoding.name,
                       ratio(unary1, "p50_us", floor_unary1, "p50_us", unary1, "in_process_us_per_pose"), 1.5, true});
    targets.push_back({"unary c8 poses/s / floor_unary c8 poses/s", encoding.name,
                       ratio(unary8, "poses_per_second", nullptr, nullptr, floor_unary8, "poses_per_second"), 0.7,
                       false});
    if (encoding.bytes_per_value == 4) continue;
    // The 16-bit encodings against float32 in the same run.
    const nlohmann::json* stream32 = find_row(rows, "stream", 1, kEncodings[0].name);
    const nlohmann::json* unary32 = find_row(rows, "unary", 1, kEncodings[0].name);
    targets.push_back({"bytes per streamed pose / float32's", encoding.name,
                       ratio(stream, "bytes_per_pose", nullptr, nullptr, stream32, "bytes_per_pose"), 0.5, true});
    std::optional<double> max_error;
    for (const nlohmann::json* row : {stream, unary1, unary8}) {
      if (row && row->contains("max_quantization_error")) {
        max_error = std::max(max_error.value_or(0.0), (*row)["max_quantization_error"].get<double>());
      }
    }
    targets.push_back({"max quantisation error / bounding-box diagonal", encoding.name,
                       max_error && diagonal > 0 ? std::optional<double>(*max_error / diagonal) : std::nullopt, 1e-4,
                       true});
    targets.push_back({"stream poses/s / float32 stream poses/s", encoding.name,
                       ratio(stream, "poses_per_second", nullptr, nullptr, stream32, "poses_per_second"), 1.0, false,
                       true});
    targets.push_back({"unary c1 poses/s / float32 unary c1 poses/s", encoding.name,
                       ratio(unary1, "poses_per_second", nullptr, nullptr, unary32, "poses_per_second"), 1.0, false,
                       true});
  }
  {
    // Issue #36: answers as coordinates against float32's rows of the same run.
    const nlohmann::json* stream = find_row(rows, "stream", 1, kCoordinates.name);
    const nlohmann::json* unary1 = find_row(rows, "unary", 1, kCoordinates.name);
    const nlohmann::json* unary8 = find_row(rows, "unary", 8, kCoordinates.name);
    const nlohmann::json* stream32 = find_row(rows, "stream", 1, kEncodings[0].name);
    const nlohmann::json* unary8_32 = find_row(rows, "unary", 8, kEncodings[0].name);
    targets.push_back({"daemon CPU per streamed pose / in-process float32 pose", kCoordinates.name,
                       ratio(stream, "daemon_cpu_us_per_pose", nullptr, nullptr, stream, "in_process_us_per_pose"),
                       0.15, true});
    targets.push_back({"daemon CPU per unary pose (1 caller) / in-process pose", kCoordinates.name,
                       ratio(unary1, "daemon_cpu_us_per_pose", nullptr, nullptr, unary1, "in_process_us_per_pose"),
                       0.15, true});
    targets.push_back({"1 stream poses/s / float32 1 stream poses/s", kCoordinates.name,
                       ratio(stream, "poses_per_second", nullptr, nullptr, stream32, "poses_per_second"), 10, false});
    targets.push_back({"unary c8 poses/s / float32 unary c8 poses/s", kCoordinates.name,
                       ratio(unary8, "poses_per_second", nullptr, nullptr, unary8_32, "poses_per_second"), 5, false});
    targets.push_back({"client reconstruction us per pose / in-process pose", kCoordinates.name,
                       ratio(stream, "client_reconstruct_us", nullptr, nullptr, stream, "in_process_us_per_pose"), 0,
                       false, true});
  }
  const nlohmann::json* batch = find_row(rows, "in_process_batch" + std::to_string(kGemmBatchPoses), 1);
  targets.push_back({"in_process_batch64 poses/s / openblas sgemm poses/s", "",
                     ratio(batch, "poses_per_second", nullptr, nullptr, batch, "openblas_sgemm_poses_per_second"), 0.8,
                     false});

  std::printf("\ntargets (issues #25 and #36):\n");
  nlohmann::json list = nlohmann::json::array();
  for (const Target& t : targets) {
    const bool met = t.measured && (t.at_most ? *t.measured <= t.limit : *t.measured >= t.limit);
    if (t.reported_only) {
      std::printf("  %-56s %-7s %8.3g (reported)\n", t.name.c_str(), t.encoding.c_str(), t.measured.value_or(0));
      list.push_back({{"figure", t.name}, {"measured", t.measured ? nlohmann::json(*t.measured) : nlohmann::json()}});
    } else {
      std::printf("  %-56s %-7s %8.3g %s %-6.3g  %s\n", t.name.c_str(), t.encoding.c_str(), t.measured.value_or(0),
                  t.at_most ? "<=" : ">=", t.limit, t.measured ? (met ? "met" : "NOT MET") : "not measured");
      list.push_back({{"target", t.name},
                      {"measured", t.measured ? nlohmann::json(*t.measured) : nlohmann::json()},
                      {"limit", t.limit},
                      {"comparison", t.at_most ? "<=" : ">="},
                      {"met", met}});
    }
    if (!t.encoding.empty()) list.back()["encoding"] = t.encoding;
  }
  std::fflush(stdout);
  return {{"mode", "targets"}, {"targets", list}};
}

}  // namespace

nlohmann::json run_serve_suite(const SuiteOptions& options) {
  std::vector<nlohmann::json> results;
  auto split = train_crane_even(options, "serve");
  if (!split) return nlohmann::json::array();
  const FrameMatrix& all = split->sequence.frames.samples;
  const std::vector<int>& even = split->even;
  const std::vector<int>& odd = split->odd;
  const pmsc::PmscModel& model = split->model;

  Workload work;
  work.point_count = model.point_count;
  work.key_count = model.key_point_count();
  work.basis_size = model.basis_size();
  pmsc::CachedPose cached;
  for (int f : odd) {
    const Eigen::VectorXf frame = all.row(f).transpose();
    work.keys.push_back(pmsc::gather_key_values(model, frame));
    work.packed_keys.push_back(pack_floats(work.keys.back()));
    pmsc::evaluate_cached(model, work.keys.back(), nullptr, cached);
    work.expected.push_back(cached.status);
    work.expected_points.push_back(cached.points);
  }
  {
    Eigen::Vector3f low = Eigen::Vector3f::Constant(std::numeric_limits<float>::max()), high = -low;
    for (const Eigen::VectorXf& answer : work.expected_points) {
      const auto points = Eigen::Map<const Eigen::Matrix3Xf>(answer.data(), 3, answer.size() / 3);
      low = low.cwiseMin(points.rowwise().minCoeff());
      high = high.cwiseMax(points.rowwise().maxCoeff());
    }
    work.diagonal = static_cast<double>((high - low).norm());
  }
  std::printf("serve: crane trained on %zu even frames: N = %d points, M = %d, K = %d keys (basis %.1f MB float); "
              "replaying the %zu odd frames; %zu bytes of points per answer\n",
              even.size(), model.point_count, model.basis_size(), model.key_point_count(),
              1e-6 * sizeof(float) * static_cast<double>(model.basis.size()), odd.size(),
              sizeof(float) * 3 * static_cast<size_t>(model.point_count));

  std::unique_ptr<ScratchDirectory> scratch_owner;
  try {
    scratch_owner = std::make_unique<ScratchDirectory>("serve");
  } catch (const std::exception& e) {
    std::printf("serve: %s\n", e.what());
    return nlohmann::json::array();
  }
  const ScratchDirectory& scratch = *scratch_owner;
  const auto repository = scratch.path() / "repository";
  if (!write_crane_repository(*split, repository, "serve")) return nlohmann::json::array();

  print_header();
  // Baselines, before any daemon exists.
  const int passes = std::max(3, options.repetitions);
  Row in_process = measure_in_process(model, work, passes, Gap::kNone);
  const double run_baseline_us = tools::quantile(in_process.latency_us, 0.5);
  auto measured = [&](Row row) {
    row.load_average = load_average_1m();
    report(row, run_baseline_us, results);
  };
  measured(std::move(in_process));
  measured(measure_in_process(model, work, std::max(1, passes / 7), Gap::kSleep));
  measured(measure_in_process(model, work, std::max(1, passes / 7), Gap::kSpin));
  measured(measure_in_process_parallel(model, work, 2));
  measured(measure_in_process_batch(model, work, kBatchPoses, 4 * passes, false, false));
  measured(measure_in_process_batch(model, work, kBatchPoses, passes, true, false));
  measured(measure_in_process_batch(model, work, kGemmBatchPoses, passes, false, true));
  auto [encode, decode] = measure_protobuf(work, 8 * passes);
  measured(std::move(encode));
  measured(std::move(decode));

  // Served rows, each between two in-process passes over the odd frames.
  auto served = [&](auto&& measure, std::optional<int> work_threads) {
    std::vector<double> around = evaluate_poses(model, work, 1);
    Row row = measure();
    const std::vector<double> after = evaluate_poses(model, work, 1);
    around.insert(around.end(), after.begin(), after.end());
    row.baseline_us = tools::quantile(around, 0.5);
    row.work_threads = work_threads;
    measured(std::move(row));
  };
  // One floor per encoding, started once: idle, it costs nothing while the daemon rows run.
  std::vector<std::unique_ptr<harness::DaemonProcess>> floors;
  for (const Encoding& encoding : kEncodings) floors.push_back(start_floor(scratch, work, encoding));
  for (int work_threads : {0, 1}) {
    auto daemon = start_daemon(scratch, repository, work_threads, model, work);
    if (!daemon) return results;
    const Endpoint endpoint{daemon->address(), daemon->pid(), false};
    auto unary = [&](const Endpoint& server, const Encoding& encoding, int concurrency, bool per_thread, bool omit) {
      served(
          [&] {
            Row row = measure_unary(server, work, encoding, concurrency, per_thread, omit);
            reconstruct_samples(server.address, work, row);
            return row;
          },
          server.floor ? std::nullopt : std::optional<int>(work_threads));
    };
    auto stream = [&](const Endpoint& server, const Encoding& encoding, int streams, bool omit) {
      served(
          [&] {
            Row row = measure_stream(server, work, encoding, streams, omit);
            reconstruct_samples(server.address, work, row);
            return row;
          },
          server.floor ? std::nullopt : std::optional<int>(work_threads));
    };
    const Encoding& float32 = kEncodings[0];
    if (work_threads == 1) {
      unary(endpoint, float32, 1, false, false);
      unary(endpoint, float32, 4, false, false);
      stream(endpoint, float32, 1, false);
      stream(endpoint, float32, 2, false);
      continue;
    }
    served([&] { return measure_round_trip(endpoint.address, endpoint.pid); }, work_threads);
    // Each floor row right before the daemon row it is the floor of (the machine's speed drifts).
    for (size_t e = 0; e < std::size(kEncodings); ++e) {
      const Encoding& encoding = kEncodings[e];
      const std::optional<Endpoint> floor =
          floors[e] ? std::optional<Endpoint>({floors[e]->address(), floors[e]->pid(), true}) : std::nullopt;
      if (floor) unary(*floor, encoding, 1, false, false);
      unary(endpoint, encoding, 1, false, false);
      if (e == 0) {
        unary(endpoint, encoding, 1, false, true);
        for (int concurrency : {4, 16}) {
          unary(endpoint, encoding, concurrency, false, false);
          unary(endpoint, encoding, concurrency, true, false);
        }
      }
      if (floor) unary(*floor, encoding, 8, false, false);
      unary(endpoint, encoding, 8, false, false);
      if (floor) stream(*floor, encoding, 1, false);
      stream(endpoint, encoding, 1, false);
      if (e == 0) {
        stream(endpoint, encoding, 2, false);
        stream(endpoint, encoding, 1, true);
        // Coordinates (issue #36) right after the float32 rows they are set against.
        unary(endpoint, kCoordinates, 1, false, false);
        unary(endpoint, kCoordinates, 8, false, false);
        stream(endpoint, kCoordinates, 1, false);
      }
    }
  }
  floors.clear();
  compare_with_floors(results);
  results.push_back(print_targets(results, work.diagonal));

  std::printf(
      "conc: client threads (in_process: evaluating threads; stream: concurrent streams). variant: unary channel use; "
      "wt=1: the daemon ran with --work-threads 1 (else one per core). p50/p99: per call (unary, describe_key_points), "
      "per pose (in_process; batch: per pose of each batch), per response (encode/decode), send→result per frame "
      "including the frames queued ahead of it (stream). base: in-process µs per pose measured right before and after "
      "the row (baseline rows: the first in_process row). d cpu / c cpu: CPU µs per pose spent by the daemon / this "
      "client (floor rows: the floor process's); dcpu/b: d cpu over base. enc: points encoding of the answers; B/pose: "
      "response bytes received per pose. mism: answers whose soft-cache status differs from the in-process one (not "
      "checked for the floor's canned answers). load: 1-minute load average.\n");
  return results;
}

}  // namespace animspace::bench
