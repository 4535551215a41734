// Admission control: at most `limit` calls are admitted at once (--max-concurrent-calls). A call
// beyond it is answered RESOURCE_EXHAUSTED at once instead of waiting in an unbounded queue, so
// an overloaded replica sheds load quickly and a load balancer can send the call elsewhere.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>

namespace animspace::server {

class Admission {
 public:
  explicit Admission(uint32_t limit) : limit_(limit) {}

  // Holds one admitted call; releases it when destroyed (or on release()).
  class Ticket {
   public:
    explicit Ticket(Admission& admission) : admission_(&admission) {}
    ~Ticket() { release(); }
    Ticket(const Ticket&) = delete;
    Ticket& operator=(const Ticket&) = delete;
    void release() {
      if (admission_ != nullptr) admission_->admitted_.fetch_sub(1, std::memory_order_acq_rel);
      admission_ = nullptr;
    }

   private:
    Admission* admission_;
  };

  // A ticket when a slot is free, else null.
  std::shared_ptr<Ticket> try_admit() {
    uint32_t current = admitted_.load(std::memory_order_relaxed);
    do {
      if (current >= limit_) return nullptr;
    } while (!admitted_.compare_exchange_weak(current, current + 1, std::memory_order_acq_rel));
    return std::make_shared<Ticket>(*this);
  }

  uint32_t admitted() const { return admitted_.load(std::memory_order_relaxed); }
  uint32_t limit() const { return limit_; }

 private:
  const uint32_t limit_;
  std::atomic<uint32_t> admitted_{0};
};

}  // namespace animspace::server
