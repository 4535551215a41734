#include "loadtest/runner.h"

#include <arpa/inet.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <thread>

namespace animspace::loadtest {
namespace {

using Clock = std::chrono::steady_clock;

Error invalid(std::string message) { return Error{ErrorCode::kInvalidArgument, std::move(message)}; }

// "a.b.c.d:port" → true (IPv4 literal); "[v6]:port" → true with `v6` set.
bool is_ip_literal(const std::string& address, bool* v6) {
  const auto colon = address.rfind(':');
  if (colon == std::string::npos || colon + 1 == address.size()) return false;
  std::string host = address.substr(0, colon);
  *v6 = host.size() > 2 && host.front() == '[' && host.back() == ']';
  if (*v6) host = host.substr(1, host.size() - 2);
  unsigned char buffer[16];
  return inet_pton(*v6 ? AF_INET6 : AF_INET, host.c_str(), buffer) == 1;
}

// What one caller saw; merged into the step's result at the end (no sharing while timing).
struct Tally {
  uint64_t requests = 0;
  uint64_t ok = 0;
  std::map<std::string, uint64_t> errors;
  uint64_t poses = 0, hits = 0, blends = 0, misses = 0;
  LatencyHistogram latency;
  std::vector<Second> timeline;

  Second& second_at(Clock::time_point when, Clock::time_point step_start) {
    const auto index = static_cast<size_t>(std::max<int64_t>(
        0, std::chrono::duration_cast<std::chrono::seconds>(when - step_start).count()));
    if (timeline.size() <= index) timeline.resize(index + 1);
    return timeline[index];
  }
  void success(Clock::time_point sent, Clock::time_point done, Clock::time_point step_start) {
    ++ok;
    latency.record(std::chrono::duration_cast<std::chrono::nanoseconds>(done - sent).count());
    ++second_at(done, step_start).ok;
  }
  void verdict(v1::CacheStatus status, Clock::time_point done, Clock::time_point step_start) {
    Second& s = second_at(done, step_start);
    ++poses;
    ++s.poses;
    if (status == v1::CACHE_STATUS_HIT) ++hits, ++s.hits;
    if (status == v1::CACHE_STATUS_BLEND) ++blends, ++s.blends;
    if (status == v1::CACHE_STATUS_MISS) ++misses, ++s.misses;
  }
  void failure(const std::string& code, Clock::time_point when, Clock::time_point step_start, uint64_t count = 1) {
    errors[code] += count;
    second_at(when, step_start).errors += count;
  }
};

void merge(StepResult& out, const Tally& t) {
  out.requests += t.requests;
  out.ok += t.ok;
  for (const auto& [code, count] : t.errors) out.errors[code] += count;
  out.poses += t.poses;
  out.hits += t.hits;
  out.blends += t.blends;
  out.misses += t.misses;
  out.latency.merge(t.latency);
  if (out.timeline.size() < t.timeline.size()) out.timeline.resize(t.timeline.size());
  for (size_t i = 0; i < t.timeline.size(); ++i) {
    Second& s = out.timeline[i];
    s.ok += t.timeline[i].ok;
    s.errors += t.timeline[i].errors;
    s.poses += t.timeline[i].poses;
    s.hits += t.timeline[i].hits;
    s.blends += t.timeline[i].blends;
    s.misses += t.timeline[i].misses;
  }
}

// One unary call carrying `batch` consecutive frames from `cursor` (wrapping), recorded in `t`.
void unary_call(const Workload& w, Client& client, size_t cursor, Clock::time_point sent, Clock::time_point step_start,
                Tally& t) {
  const size_t n = w.frame_count();
  try {
    if (w.rpc == Rpc::kSkinning) {
      std::vector<SkeletonPose> poses;
      for (uint32_t b = 0; b < w.batch; ++b) poses.push_back(w.skeleton_poses[(cursor + b) % n]);
      SkinningOptions options;
      options.version = w.version;
      const SkinningResult result = client.evaluate_skeleton_pose(w.model, poses, options);
      const auto done = Clock::now();
      t.success(sent, done, step_start);
      t.poses += result.poses.size();
      t.second_at(done, step_start).poses += result.poses.size();
      return;
    }
    std::vector<KeyPointPose> poses;
    for (uint32_t b = 0; b < w.batch; ++b) {
      KeyPointPose pose{w.key_frames[(cursor + b) % n], w.channel_count};
      pose.check_values = w.check_frames[(cursor + b) % n];
      poses.push_back(pose);
    }
    EvaluateOptions options;
    options.version = w.version;
    options.omit_points = w.omit_points;
    options.points_encoding = w.points_encoding;
    options.skip_miss_log = w.skip_miss_log;
    const std::vector<PoseResult> results = client.evaluate_key_points_batch(w.model, poses, options);
    const auto done = Clock::now();
    t.success(sent, done, step_start);
    for (const PoseResult& r : results) t.verdict(r.status, done, step_start);
  } catch (const RpcError& error) {
    t.failure(status_code_name(error.code()), Clock::now(), step_start);
  } catch (const std::exception&) {
    t.failure("CLIENT", Clock::now(), step_start);  // an answer that broke the protocol
  }
}

// A closed-loop caller on a stream: a writer keeps up to `window` frames in flight; each frame's
// latency runs from its write to its answer. A failed stream counts its unanswered frames as
// errors with the stream's status, and the caller opens a new one.
void stream_caller(const Workload& w, Client& client, const StepPlan& plan, size_t first_frame, Clock::time_point stop,
                   std::atomic<uint64_t>& budget, Clock::time_point step_start, Tally& t) {
  size_t cursor = first_frame;
  while (Clock::now() < stop && budget.load() < plan.max_requests) {
    StreamOptions options;
    options.version = w.version;
    options.omit_points = w.omit_points;
    options.points_encoding = w.points_encoding;
    options.skip_miss_log = w.skip_miss_log;
    options.window = plan.stream_window;
    auto stream = client.open_stream(w.model, options);
    std::mutex mutex;
    std::deque<Clock::time_point> sent;  // write times of the unanswered frames, oldest first
    uint64_t written = 0;
    std::thread writer([&] {
      uint64_t sequence = 0;
      while (Clock::now() < stop && budget.fetch_add(1) < plan.max_requests) {
        {
          std::lock_guard lock(mutex);
          sent.push_back(Clock::now());
        }
        KeyPointPose pose{w.key_frames[cursor % w.frame_count()], w.channel_count};
        pose.check_values = w.check_frames[cursor % w.frame_count()];
        if (!stream->write(pose, sequence++)) break;
        ++written;
        ++cursor;
      }
      stream->writes_done();
    });
    uint64_t answered = 0;
    std::string failure;
    try {
      while (auto result = stream->read()) {
        const auto done = Clock::now();
        Clock::time_point when;
        {
          std::lock_guard lock(mutex);
          when = sent.front();
          sent.pop_front();
        }
        ++answered;
        t.success(when, done, step_start);
        t.verdict(result->status, done, step_start);
      }
    } catch (const std::exception&) {
      failure = "CLIENT";
      stream->cancel();
    }
    writer.join();
    t.requests += written;
    if (failure.empty()) {
      try {
        stream->finish();
      } catch (const RpcError& error) {
        failure = status_code_name(error.code());
      }
    }
    if (!failure.empty()) t.failure(failure, Clock::now(), step_start, std::max<uint64_t>(1, written - answered));
  }
}

}  // namespace

uint64_t StepResult::error_count() const {
  uint64_t n = 0;
  for (const auto& [code, count] : errors) n += count;
  return n;
}

Result<Targets> connect_targets(const std::vector<std::string>& servers, const ClientOptions& options) {
  if (servers.empty()) return invalid("--server: give at least one address");
  std::string target = servers.front();
  if (servers.size() > 1) {
    bool first_v6 = false;
    std::string joined;
    for (const std::string& s : servers) {
      bool v6 = false;
      if (!is_ip_literal(s, &v6)) {
        return invalid("--server " + s + ": several servers are balanced as one ipv4:/ipv6: target, so each must be "
                       "an IP address with a port; for names give one DNS name that resolves to every replica "
                       "(e.g. dns:///animspaced-headless:50051)");
      }
      if (&s == &servers.front()) first_v6 = v6;
      if (v6 != first_v6) return invalid("--server " + s + ": IPv4 and IPv6 addresses cannot be mixed");
      joined += (joined.empty() ? "" : ",") + s;
    }
    target = (first_v6 ? "ipv6:" : "ipv4:") + joined;
  }
  grpc::ChannelArguments args;
  args.SetLoadBalancingPolicyName("round_robin");
  args.SetMaxReceiveMessageSize(options.max_receive_message_bytes);
  // Its own connections, not shared with the statistics clients' channels.
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  const auto credentials = grpc::InsecureChannelCredentials();
  Targets out;
  out.servers = servers;
  out.load = std::make_unique<Client>(grpc::CreateCustomChannel(target, credentials, args), options);
  for (const std::string& s : servers) out.per_server.push_back(std::make_unique<Client>(s, options));
  return out;
}

ServerCounters read_server_counters(Targets& targets, const std::string& model) {
  ServerCounters sum;
  for (auto& client : targets.per_server) {
    // Every model's counters: a GetStats naming the model would count itself as one of its requests.
    const v1::GetStatsResponse stats = client->stats();
    for (const auto& m : stats.models()) {
      if (m.model() != model) continue;
      sum.requests += m.requests();
      sum.poses += m.poses();
      sum.hits += m.hits();
      sum.blends += m.blends();
      sum.misses += m.misses();
      sum.errors += m.errors();
    }
  }
  return sum;
}

double scheduled_time(uint64_t k, double r0, double r1, double T) {
  const double n = static_cast<double>(k);
  const double a = (r1 - r0) / (2 * T);  // ∫₀ᵗ r = r0·t + a·t²
  if (std::abs(a) < 1e-12 * std::max(1.0, r0)) return n / r0;
  const double discriminant = r0 * r0 + 4 * a * n;
  if (discriminant < 0) return std::numeric_limits<double>::infinity();  // a falling ramp never gets there
  return (-r0 + std::sqrt(discriminant)) / (2 * a);
}

StepResult run_step(const Workload& w, Targets& targets, const StepPlan& plan, Clock::time_point run_start) {
  StepResult out;
  out.plan = plan;
  out.server_before = read_server_counters(targets, w.model);
  const auto start = Clock::now();
  out.start_s = std::chrono::duration<double>(start - run_start).count();
  const auto stop = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(plan.duration_s));
  const size_t frames = w.frame_count();
  const uint32_t callers = std::max(1u, plan.concurrency);
  std::vector<Tally> tallies(callers);
  std::atomic<uint64_t> budget{0};
  Client& client = *targets.load;

  std::vector<std::thread> threads;
  if (!plan.open_loop) {
    for (uint32_t c = 0; c < callers; ++c) {
      // Callers start at different places in the sequence, like clients playing different shots.
      const size_t first = frames * c / callers;
      threads.emplace_back([&, c, first] {
        Tally& t = tallies[c];
        if (w.rpc == Rpc::kStream) {
          stream_caller(w, client, plan, first, stop, budget, start, t);
          return;
        }
        size_t cursor = first;
        while (Clock::now() < stop && budget.fetch_add(1) < plan.max_requests) {
          ++t.requests;
          unary_call(w, client, cursor, Clock::now(), start, t);
          cursor += w.batch;
        }
      });
    }
    for (auto& thread : threads) thread.join();
  } else {
    // The schedule is fixed before anything answers: request k is due at scheduled_time(k).
    std::mutex mutex;
    std::condition_variable ready;
    std::deque<std::pair<uint64_t, Clock::time_point>> due;  // (k, when)
    bool closed = false;
    for (uint32_t c = 0; c < callers; ++c) {
      threads.emplace_back([&, c] {
        Tally& t = tallies[c];
        while (true) {
          std::pair<uint64_t, Clock::time_point> job;
          {
            std::unique_lock lock(mutex);
            ready.wait(lock, [&] { return closed || !due.empty(); });
            if (due.empty()) return;
            job = due.front();
            due.pop_front();
          }
          std::this_thread::sleep_until(job.second);
          if (Clock::now() >= stop) continue;  // due too late for this step: left unsent
          ++t.requests;
          unary_call(w, client, (job.first * w.batch) % frames, job.second, start, t);
        }
      });
    }
    uint64_t k = 0;
    for (; k < plan.max_requests; ++k) {
      const double at = scheduled_time(k, plan.rate_start, plan.rate_end, plan.duration_s);
      if (!(at < plan.duration_s)) break;
      const auto when = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(at));
      // Release requests a little ahead of time, so a worker is already waiting for each.
      std::this_thread::sleep_until(when - std::chrono::milliseconds(2));
      {
        std::lock_guard lock(mutex);
        due.emplace_back(k, when);
      }
      ready.notify_one();
    }
    {
      std::lock_guard lock(mutex);
      closed = true;
    }
    ready.notify_all();
    for (auto& thread : threads) thread.join();
    uint64_t started = 0;
    for (const Tally& t : tallies) started += t.requests;
    out.unsent = k - started;
  }
  out.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  for (const Tally& t : tallies) merge(out, t);
  out.server_after = read_server_counters(targets, w.model);
  return out;
}

}  // namespace animspace::loadtest
