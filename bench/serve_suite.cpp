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
#include <memory>
#include <numeric>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "animspace/v1/poses.grpc.pb.h"
#include "bench/crane_split.h"
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
// How long a server thread sleeps between requests in the *_after_idle baselines.
constexpr auto kIdleGap = std::chrono::milliseconds(1);

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
  std::optional<int> work_threads;  // served rows: the daemon's --work-threads (0 = one per core)
  long poses = 0;
  double seconds = 0;
  std::vector<double> latency_us;  // per call (unary), per frame send → result (stream), per pose
  std::optional<double> baseline_us;  // in-process µs per pose measured around this row
  Outcomes outcomes;
  std::optional<double> daemon_cpu_seconds, client_cpu_seconds;
  double load_average = 0;
  std::string error;  // first failure, if any
  bool in_order = true;
};

// The served model's inputs: the odd frames' key values packed as the wire expects, with the
// in-process verdict and points of each.
struct Workload {
  int point_count = 0;  // N
  int key_count = 0;    // K
  std::vector<Eigen::VectorXf> keys;
  std::vector<std::string> packed_keys;  // K·3 little-endian float32
  std::vector<pmsc::CacheStatus> expected;
  std::vector<Eigen::VectorXf> expected_points;
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

// evaluate_batch on kBatchPoses poses at a time; latency_us holds µs per pose of each batch.
Row measure_in_process_batch(const pmsc::PmscModel& model, const Workload& work, int batches, bool after_idle) {
  Row row(after_idle ? "in_process_batch_after_idle" : "in_process_batch");
  Eigen::MatrixXf keys(work.keys.front().size(), kBatchPoses);
  Eigen::MatrixXf points;
  Eigen::VectorXd errors;
  for (int batch = -1; batch < batches; ++batch) {  // batch −1 warms up
    for (long b = 0; b < kBatchPoses; ++b) {
      keys.col(b) = work.keys[static_cast<size_t>((batch + 1) * kBatchPoses + b) % work.keys.size()];
    }
    if (after_idle) std::this_thread::sleep_for(kIdleGap);
    const auto start = Clock::now();
    pmsc::evaluate_batch(model, keys, points, errors);
    do_not_optimize(points.data());
    if (batch >= 0) row.latency_us.push_back(1e6 * seconds_since(start) / kBatchPoses);
  }
  row.poses = static_cast<long>(row.latency_us.size()) * kBatchPoses;
  // Throughput from the evaluation time alone (the idle gaps and key copies excluded).
  row.seconds = std::accumulate(row.latency_us.begin(), row.latency_us.end(), 0.0) * kBatchPoses * 1e-6;
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
std::vector<v1::EvaluateKeyPointsRequest> unary_requests(const Workload& work, bool omit_points) {
  std::vector<v1::EvaluateKeyPointsRequest> requests(work.packed_keys.size());
  for (size_t f = 0; f < requests.size(); ++f) {
    requests[f].mutable_model()->set_name(kModelName);
    *requests[f].add_poses()->mutable_key_values() = point_array(work.packed_keys[f], work.key_count);
    requests[f].set_omit_points(omit_points);
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

// `concurrency` threads, each with its own stub (on one shared channel or on its own), calling
// EvaluateKeyPoints back to back for kMeasureSeconds after a warm-up.
Row measure_unary(const std::string& address, pid_t daemon, const Workload& work, int concurrency,
                  bool channel_per_thread, bool omit_points) {
  Row row(omit_points ? "unary_omit_points" : "unary", concurrency);
  row.channels = channel_per_thread ? "per-thread" : "shared";
  const auto requests = unary_requests(work, omit_points);
  const auto shared = make_channel(address, false);
  const size_t expected_bytes = omit_points ? 0 : sizeof(float) * 3 * static_cast<size_t>(work.point_count);

  struct Worker {
    std::vector<double> latency_us;
    Outcomes outcomes;
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
      if (response.results_size() != 1 || response.results(0).points().data().size() != expected_bytes) {
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
      me.outcomes.add(response.results(0).status(), work.expected[frame]);
    }
  };

  std::vector<std::thread> threads;
  for (int t = 0; t < concurrency; ++t) threads.emplace_back(body, t);
  while (ready.load() < concurrency) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  CpuMeter cpu(daemon);
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
  auto call = [&]() -> bool {
    grpc::ClientContext context;
    v1::DescribeKeyPointsResponse response;
    const grpc::Status status = stub->DescribeKeyPoints(&context, request, &response);
    if (!status.ok()) row.error = "DescribeKeyPoints: " + status.error_message();
    return status.ok();
  };
  for (const auto warm_until = Clock::now() + std::chrono::duration<double>(kWarmupSeconds);
       Clock::now() < warm_until && call();) {
  }
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
  return row;
}

// `streams` StreamKeyPoints calls at once, each replaying kStreamFrames frames (the odd frames
// looped) from a writer thread while its reader checks that results arrive in order. The writer
// never waits for results, so the latency of a frame includes every frame queued ahead of it.
Row measure_stream(const std::string& address, pid_t daemon, const Workload& work, int streams, bool omit_points) {
  Row row(omit_points ? "stream_omit_points" : "stream", streams);
  const size_t expected_bytes = omit_points ? 0 : sizeof(float) * 3 * static_cast<size_t>(work.point_count);
  std::vector<v1::KeyPointFrame> frames(work.packed_keys.size());
  for (size_t f = 0; f < frames.size(); ++f) {
    *frames[f].mutable_pose()->mutable_key_values() = point_array(work.packed_keys[f], work.key_count);
    frames[f].set_omit_points(omit_points);
  }
  const auto channel = make_channel(address, false);

  struct StreamState {
    std::unique_ptr<v1::PoseService::Stub> stub;
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReaderWriter<v1::KeyPointFrame, v1::PoseResult>> call;
    std::vector<std::atomic<int64_t>> sent_ns = std::vector<std::atomic<int64_t>>(kStreamFrames);
    std::vector<double> latency_us;
    Outcomes outcomes;
    bool in_order = true;
    long received = 0;
    std::string error;
  };
  std::vector<std::unique_ptr<StreamState>> states;
  for (int s = 0; s < streams; ++s) {
    auto state = std::make_unique<StreamState>();
    state->stub = v1::PoseService::NewStub(channel);
    state->call = state->stub->StreamKeyPoints(&state->context);
    states.push_back(std::move(state));
  }

  CpuMeter cpu(daemon);
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
        if (result.points().data().size() != expected_bytes && state->error.empty()) {
          state->error = "stream: unexpected result shape";
        }
        const size_t index = static_cast<size_t>(result.sequence() % static_cast<uint64_t>(kStreamFrames));
        state->latency_us.push_back(
            1e-3 * static_cast<double>(now_ns() - state->sent_ns[index].load(std::memory_order_acquire)));
        state->outcomes.add(result.status(), work.expected[index % work.expected.size()]);
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
  }
  return row;
}

// ---------------------------------------------------------------------------------------------
// Reporting

void print_header() {
  std::printf("%-27s %4s %-10s %9s %9s %9s %8s %6s %6s %6s %6s %4s %5s\n", "mode", "conc", "variant", "poses/s",
              "p50 us", "p99 us", "base us", "dcpu/b", "d cpu", "c cpu", "hit", "mism", "load");
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
  if (row.mode.starts_with("stream")) json["in_order"] = row.in_order;
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
  if (row.mode.starts_with("stream") && !row.in_order && row.error.empty()) json["error"] = "results out of order";
  const std::string error = json.contains("error") ? " ERROR " + json["error"].get<std::string>() : "";
  std::printf("%-27s %4d %-10s %9.0f %9.1f %9.1f %8.1f %6s %6s %6s %6s %4s %5.1f%s\n", row.mode.c_str(),
              row.concurrency, variant.empty() ? "-" : variant.c_str(), pps, p50, p99, baseline, daemon_ratio,
              daemon_cpu, client_cpu, hit, mismatched, row.load_average, error.c_str());
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
  pmsc::CachedPose cached;
  for (int f : odd) {
    const Eigen::VectorXf frame = all.row(f).transpose();
    work.keys.push_back(pmsc::gather_key_values(model, frame));
    work.packed_keys.push_back(pack_floats(work.keys.back()));
    pmsc::evaluate_cached(model, work.keys.back(), nullptr, cached);
    work.expected.push_back(cached.status);
    work.expected_points.push_back(cached.points);
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
  measured(measure_in_process_batch(model, work, 4 * passes, false));
  measured(measure_in_process_batch(model, work, passes, true));
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
  for (int work_threads : {0, 1}) {
    auto daemon = start_daemon(scratch, repository, work_threads, model, work);
    if (!daemon) return results;
    const std::string address = daemon->address();
    const pid_t pid = daemon->pid();
    auto unary = [&](int concurrency, bool per_thread, bool omit) {
      served([&] { return measure_unary(address, pid, work, concurrency, per_thread, omit); }, work_threads);
    };
    auto stream = [&](int streams, bool omit) {
      served([&] { return measure_stream(address, pid, work, streams, omit); }, work_threads);
    };
    if (work_threads == 0) served([&] { return measure_round_trip(address, pid); }, work_threads);
    unary(1, false, false);
    if (work_threads == 0) {
      unary(1, false, true);
      for (int concurrency : {4, 16}) {
        unary(concurrency, false, false);
        unary(concurrency, true, false);
      }
    } else {
      unary(4, false, false);
    }
    stream(1, false);
    stream(2, false);
    if (work_threads == 0) stream(1, true);
  }

  std::printf(
      "conc: client threads (in_process: evaluating threads; stream: concurrent streams). variant: unary channel use; "
      "wt=1: the daemon ran with --work-threads 1 (else one per core). p50/p99: per call (unary, describe_key_points), "
      "per pose (in_process; batch: per pose of each batch), per response (encode/decode), send→result per frame "
      "including the frames queued ahead of it (stream). base: in-process µs per pose measured right before and after "
      "the row (baseline rows: the first in_process row). d cpu / c cpu: CPU µs per pose spent by the daemon / this "
      "client; dcpu/b: d cpu over base. mism: answers whose soft-cache status differs from the in-process one. load: "
      "1-minute load average.\n");
  return results;
}

}  // namespace animspace::bench
