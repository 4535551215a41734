// The one skeleton of a streaming call, shared by PoseService.StreamKeyPoints (bidi) and
// LodService.GetLod (server streaming): the services keep only what their messages mean.
//
// Ordered, pipelined writes. Every response is produced by work on the request pool and takes a
// slot, reserved in order when the work is submitted. Slots are written front to back with one
// write outstanding (gRPC allows no more), so work may finish in any order and several units may
// run at once while earlier responses are on the wire. A slot may instead end the stream with a
// status (the input is exhausted, or an error): the call finishes with it once every slot before
// it is written, and work queued behind it is discarded.
//
// One lifetime rule. A count of holds: gRPC holds the reactor from creation to OnDone, and each
// task submitted to the pool holds it until the task returns. Whoever drops the last hold deletes
// it. A finished call therefore never waits for work it will not write (a cancelled stream ends at
// once), and a task that outlives OnDone still runs against a live reactor, finds the call over
// and drops its result. After OnDone gRPC frees the context and the request, so work reads neither:
// stop_status() answers from the reactor's own state, and services copy what they need on arrival.
// (Before this rule each stream kept itself alive with flags and counters of its own, and
// StreamKeyPoints was once deleted under a pool thread still inside it: the use-after-free fixed
// in commit 8510907.)
//
// Stalls (issue #54 item 6). A client may stop granting flow-control window and leave a write in
// flight forever, holding a call slot and the message. A check every half --stream-stall-ms
// cancels the stream whose write has waited longer than that; each check is its own grpc::Alarm
// holding the reactor (an alarm may not be set again from its own callback), and OnDone cancels
// the pending one.
//
// Cancellation. OnCancel (the client went away, or the deadline passed) and a failed write stop
// all scheduling; the call finishes with CANCELLED once the write in flight is done. Finish is
// called exactly once, and never while another thread is between deciding to start a gRPC
// operation and returning from it (`starting_`): a StartRead or StartWrite issued after Finish
// could reach a call gRPC has already freed.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

#include <grpcpp/alarm.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

#include "server/admission.h"
#include "server/auth.h"
#include "server/call_scope.h"
#include "server/metrics.h"
#include "server/unary_call.h"
#include "server/work_pool.h"

namespace animspace::server {

// `Base` is grpc::ServerWriteReactor<Response> or grpc::ServerBidiReactor<Request, Response>.
template <typename Base, typename Response>
class StreamReactor : public Base {
 public:
  // What one unit of work yields: a response to write, or (no response) the end of the stream
  // with `status`, OK for a stream that is complete.
  struct Outcome {
    std::optional<Response> response;
    grpc::Status status;
    static Outcome write(Response response) { return {std::move(response), grpc::Status::OK}; }
    static Outcome end(grpc::Status status) { return {std::nullopt, std::move(status)}; }
  };

  void OnWriteDone(bool ok) final {
    {
      std::lock_guard lock(mutex_);
      writing_ = false;
      slots_.pop_front();
      // Not ok: the client is gone (or cancelled); nothing more can be delivered.
      if (!ok) cancelled_ = true;
    }
    pump();
  }

  void OnCancel() final {
    {
      std::lock_guard lock(mutex_);
      cancelled_ = true;
    }
    pump();
  }

  // Cancels the stall check and drops gRPC's hold. An override (tests observe the call's end)
  // must end with this one.
  void OnDone() override {
    std::unique_ptr<grpc::Alarm> check;
    {
      std::lock_guard lock(mutex_);
      done_ = true;
      check = std::move(stall_check_);
    }
    check.reset();  // outside the lock: its callback (fired false) takes it
    release();
  }

 protected:
  // `rpc` as in metrics ("PoseService/StreamKeyPoints"). Call from the method handler, which
  // owns `context` until OnDone.
  StreamReactor(grpc::CallbackServerContext* context, WorkPool& pool, Metrics& metrics, std::string_view rpc)
      : context_(context), deadline_(context->deadline()), pool_(pool), scope_(metrics, rpc), rpc_(rpc) {}

  // The call's deadline (time_point::max() when the client set none).
  std::chrono::system_clock::time_point deadline() const { return deadline_; }

  // Authenticates and admits the call as unary calls are (server/unary_call.h). False when
  // refused: the call is then finished.
  bool admit(ServiceEnvironment& env, Access access) {
    if (grpc::Status refused = server::admit(env, context_, rpc_, access, &ticket_); !refused.ok()) {
      finish_early(std::move(refused));
      return false;
    }
    stall_timeout_ = env.options.stream_stall_timeout;
    if (stall_timeout_.count() > 0) arm_stall_check();
    return true;
  }

  // Finishes a call that never started its stream (refused, or a request that does not parse).
  void finish_early(grpc::Status status) {
    {
      std::lock_guard lock(mutex_);
      finished_ = true;
    }
    finish_now(std::move(status));
  }

  // Runs `work` on the pool; what it yields takes the next slot. Work is skipped (its slot ends
  // the stream with stop_status()) when the call is stopped before it starts. Ignored once the
  // stream has ended or stopped. Call from a reaction or from request_more, then pump().
  void submit(std::function<Outcome()> work) {
    Slot* slot = nullptr;
    {
      std::lock_guard lock(mutex_);
      requesting_ = false;
      if (finished_ || ended_ || cancelled_) return;
      slots_.push_back(std::make_unique<Slot>());
      slot = slots_.back().get();
      ++producing_;
    }
    holds_.fetch_add(1, std::memory_order_relaxed);
    const bool queued = pool_.submit([this, slot, work = std::move(work)] {
      grpc::Status stop = stop_status();
      complete(slot, stop.ok() ? work() : Outcome::end(std::move(stop)));
      pump();
      release();
    });
    if (!queued) {
      complete(slot, Outcome::end(unavailable("the server is shutting down")));
      release();
    }
  }

  // As submit(), but runs `work` here, on the reaction thread, before returning: for work smaller
  // than a hand-off to the pool and back (a pose answered as coordinates is one projection —
  // microseconds — where the hand-off's wake-ups cost as much again). The slot is reserved first
  // and the next input asked for (pump) before the work starts, so the next read arrives, on
  // another gRPC thread, while this one computes; the work holds the reactor as a pool task does
  // (the call may finish meanwhile). Call from a reaction, as its last step: it pumps itself, and
  // the reactor may be gone when it returns.
  void run_here(const std::function<Outcome()>& work) {
    Slot* slot = nullptr;
    {
      std::lock_guard lock(mutex_);
      requesting_ = false;
      if (!finished_ && !ended_ && !cancelled_) {
        slots_.push_back(std::make_unique<Slot>());
        slot = slots_.back().get();
        ++producing_;
      }
    }
    if (slot == nullptr) {
      pump();
      return;
    }
    holds_.fetch_add(1, std::memory_order_relaxed);
    pump();
    grpc::Status stop = stop_status();
    complete(slot, stop.ok() ? work() : Outcome::end(std::move(stop)));
    pump();
    release();
  }

  // The stream ends with `status` once everything submitted before is written (the end of the
  // input, or an error found on the reaction thread). Ignored once the stream has ended.
  void end(grpc::Status status) {
    std::lock_guard lock(mutex_);
    requesting_ = false;
    if (finished_ || ended_) return;
    auto slot = std::make_unique<Slot>();
    slot->ready = true;
    slot->status = std::move(status);
    slots_.push_back(std::move(slot));
    ended_ = true;
  }

  // Starts what can start next — the front write, more input (request_more), or the finish — until
  // nothing can. Every reaction of the service ends with it.
  void pump() {
    for (;;) {
      Actions next;
      {
        std::lock_guard lock(mutex_);
        next = decide();
        if (next.write != nullptr || next.request) ++starting_;
      }
      if (next.finish) {
        finish_now(std::move(next.status));
        return;  // OnDone may run from here on; only holds keep this reactor alive
      }
      if (next.write == nullptr && !next.request) return;
      // Every write goes out at once: no buffer hint. A hinted write is not complete (no
      // OnWriteDone) until the transport flushes it, and with one write outstanding the write
      // that would flush it waits for that OnWriteDone; only unrelated traffic (the client's
      // next frames) ever flushed it. A client whose window was full sent nothing more, and the
      // stream hung under load (seen under TSan; grpc/grpc#34231 is the same for a first write).
      if (next.write != nullptr) Base::StartWrite(next.write);
      if (next.request) request_more();
      std::lock_guard lock(mutex_);
      --starting_;
      // Loop: a finish may have waited for this thread, and what it started may make room.
    }
  }

  // CANCELLED when the client cancelled or the call is already over, DEADLINE_EXCEEDED once the
  // deadline has passed, else OK. Safe from pool threads at any time, OnDone included.
  grpc::Status stop_status() const {
    {
      std::lock_guard lock(mutex_);
      if (cancelled_ || finished_) return {grpc::StatusCode::CANCELLED, "the client cancelled the stream"};
    }
    if (std::chrono::system_clock::now() >= deadline_) {
      return {grpc::StatusCode::DEADLINE_EXCEEDED, "the call's deadline passed before the work was done"};
    }
    return grpc::Status::OK;
  }

  // Labels the call's metrics and log line with a model (known to exist); ignored once finished.
  void set_model(const std::string& model) {
    std::lock_guard lock(mutex_);
    if (!finished_) scope_.set_model(model);
  }

  // Whether to ask for more now, given the slots not yet written and how many of those are still
  // being produced. Called with the reactor's lock held: decide from these counts only.
  virtual bool want_more(size_t unwritten, size_t producing) const = 0;
  // Asks for more: StartRead for a stream of requests, submit() for a producer. Called outside
  // the lock, and not again until submit() or end() has answered it.
  virtual void request_more() = 0;

 private:
  struct Slot {
    bool ready = false;
    std::optional<Response> response;  // none: the stream ends here with `status`
    grpc::Status status;
  };
  struct Actions {
    const Response* write = nullptr;
    bool request = false;
    bool finish = false;
    grpc::Status status;
  };

  // mutex_ held.
  Actions decide() {
    Actions next;
    if (finished_) return next;
    const bool quiet = !writing_ && starting_ == 0;
    if (cancelled_) {
      if (quiet) {
        next.finish = true;
        next.status = {grpc::StatusCode::CANCELLED, "the client cancelled the stream"};
      }
    } else {
      if (!writing_ && !slots_.empty() && slots_.front()->ready) {
        Slot& front = *slots_.front();
        if (front.response) {
          writing_ = true;
          write_started_ = std::chrono::steady_clock::now();
          next.write = &*front.response;
        } else if (quiet) {
          next.finish = true;
          next.status = front.status;
        }
      }
      if (!next.finish && !ended_ && !requesting_ && want_more(slots_.size(), producing_)) {
        requesting_ = true;
        next.request = true;
      }
    }
    if (next.finish) finished_ = true;
    return next;
  }

  void complete(Slot* slot, Outcome outcome) {
    std::lock_guard lock(mutex_);
    --producing_;
    slot->ready = true;
    if (outcome.response) {
      slot->response = std::move(outcome.response);
    } else {
      slot->status = std::move(outcome.status);
      ended_ = true;
    }
  }

  void finish_now(grpc::Status status) {
    if (ticket_) ticket_->release();
    Base::Finish(scope_.finish(std::move(status)));
  }

  void release() {
    if (holds_.fetch_sub(1, std::memory_order_acq_rel) == 1) delete this;
  }

  // The next stall check, half a timeout from now; it holds the reactor until its callback.
  void arm_stall_check() {
    holds_.fetch_add(1, std::memory_order_relaxed);
    auto check = std::make_unique<grpc::Alarm>();
    const auto period = std::max(stall_timeout_ / 2, std::chrono::milliseconds(10));
    check->Set(std::chrono::system_clock::now() + period, [this](bool fired) { on_stall_check(fired); });
    std::unique_ptr<grpc::Alarm> previous;  // the alarm whose callback is running, if any
    {
      std::lock_guard lock(mutex_);
      previous = std::move(stall_check_);
      if (!done_) stall_check_ = std::move(check);
    }
    // Both outside the lock: destroying a pending alarm runs its callback, which takes it.
    check.reset();
    previous.reset();
  }

  void on_stall_check(bool fired) {
    bool stalled = false;
    bool again = false;
    if (fired) {
      std::lock_guard lock(mutex_);
      if (!finished_ && !cancelled_ && !done_) {
        stalled = writing_ && std::chrono::steady_clock::now() - write_started_ >= stall_timeout_;
        // Held like a write being started: no Finish, so context_ stays valid, until TryCancel returns.
        if (stalled) ++starting_;
        again = !stalled;
      }
    }
    if (stalled) {
      spdlog::warn("{}: the client took no data for {} ms; stream cancelled (--stream-stall-ms)", rpc_,
                   stall_timeout_.count());
      context_->TryCancel();
      {
        std::lock_guard lock(mutex_);
        --starting_;
      }
      pump();
    }
    if (again) arm_stall_check();
    release();
  }

  grpc::CallbackServerContext* const context_;  // gRPC's, valid until OnDone
  const std::chrono::system_clock::time_point deadline_;
  WorkPool& pool_;
  CallScope scope_;
  const std::string rpc_;
  std::shared_ptr<Admission::Ticket> ticket_;
  std::atomic<int> holds_{1};  // gRPC's until OnDone, plus one per pool task

  mutable std::mutex mutex_;
  // Front: the next response to write. Slots are freed only once written (or with the reactor),
  // so a pool task's slot outlives the task.
  std::deque<std::unique_ptr<Slot>> slots_;
  size_t producing_ = 0;     // slots whose work has not completed
  bool writing_ = false;     // the front slot is on the wire
  int starting_ = 0;         // threads starting a write or asking for more, outside the lock
  bool requesting_ = false;  // request_more() has not been answered yet
  bool ended_ = false;       // a slot ends the stream: ask for nothing more
  bool cancelled_ = false;
  bool finished_ = false;
  bool done_ = false;  // OnDone has run: arm no more stall checks
  std::chrono::steady_clock::time_point write_started_;  // of the write on the wire
  std::chrono::milliseconds stall_timeout_{0};
  std::unique_ptr<grpc::Alarm> stall_check_;  // the pending one
};

}  // namespace animspace::server
