// The one path every unary RPC takes: authenticate, admit, run the handler body on a pool the
// server owns, record the outcome, finish. Handlers only validate and compute.
//
//   return serve_unary(env_, context, "PoseService/EvaluateKeyPoints", Access::kUser,
//                      env_.request_pool, [=](const CallControl& call) {
//                        …; return grpc::Status::OK;
//                      });
//
// Deadlines and cancellation: a call whose deadline passed or whose client went away while it
// waited in the queue is never started; long bodies poll `call.stop_status()` between units of
// work (poses of a batch, stages of a retrain) and return it.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <utility>

#include <grpcpp/grpcpp.h>

#include "server/call_scope.h"
#include "server/service_environment.h"

namespace animspace::server {

// What a handler body may ask about its call while it runs.
class CallControl {
 public:
  CallControl(grpc::CallbackServerContext* context, CallScope* scope) : context_(context), scope_(scope) {}
  // CANCELLED when the client cancelled (or went away), DEADLINE_EXCEEDED when the deadline has
  // passed, else OK.
  grpc::Status stop_status() const;
  grpc::CallbackServerContext* context() const { return context_; }
  // Labels the call's metrics and log line with a model, once the model is known to exist
  // (names of unknown models never become metric labels: a client could mint them at will).
  void set_model(const std::string& model) const {
    if (scope_ != nullptr) scope_->set_model(model);
  }

 private:
  grpc::CallbackServerContext* context_;
  CallScope* scope_;
};

// Authentication and admission, shared by unary and streaming calls. OK with a ticket, or the
// status to finish with.
grpc::Status admit(ServiceEnvironment& env, const grpc::CallbackServerContext* context, std::string_view rpc,
                   Access access, std::shared_ptr<Admission::Ticket>* ticket);

// Finishes a deferred call exactly once, from any thread: records the outcome, frees the
// admission slot and answers the client.
class CallFinisher {
 public:
  CallFinisher(grpc::ServerUnaryReactor* reactor, std::shared_ptr<CallScope> scope,
               std::shared_ptr<Admission::Ticket> ticket)
      : reactor_(reactor), scope_(std::move(scope)), ticket_(std::move(ticket)) {}
  void operator()(grpc::Status status) const {
    ticket_->release();
    reactor_->Finish(scope_->finish(std::move(status)));
  }

 private:
  grpc::ServerUnaryReactor* reactor_;
  std::shared_ptr<CallScope> scope_;
  std::shared_ptr<Admission::Ticket> ticket_;
};

// For bodies that hand the rest of their work to another thread (the render thread): the body
// runs on `pool` as in serve_unary and must make `finish(status)` happen exactly once — itself,
// or later from wherever the work ends.
template <typename Body>
grpc::ServerUnaryReactor* serve_unary_deferred(ServiceEnvironment& env, grpc::CallbackServerContext* context,
                                               const char* rpc, Access access, WorkPool& pool, Body body) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  auto scope = std::make_shared<CallScope>(env.metrics, rpc);
  std::shared_ptr<Admission::Ticket> ticket;
  if (grpc::Status refused = admit(env, context, rpc, access, &ticket); !refused.ok()) {
    reactor->Finish(scope->finish(refused));
    return reactor;
  }
  const CallFinisher finish(reactor, scope, ticket);
  const bool queued = pool.submit([context, scope, finish, body = std::move(body)]() mutable {
    const CallControl call(context, scope.get());
    if (grpc::Status stop = call.stop_status(); !stop.ok()) {
      finish(std::move(stop));
      return;
    }
    body(call, finish);
  });
  if (!queued) finish({grpc::StatusCode::UNAVAILABLE, "the server is shutting down"});
  return reactor;
}

template <typename Body>
grpc::ServerUnaryReactor* serve_unary(ServiceEnvironment& env, grpc::CallbackServerContext* context,
                                      const char* rpc, Access access, WorkPool& pool, Body body) {
  return serve_unary_deferred(env, context, rpc, access, pool,
                              [body = std::move(body)](const CallControl& call, const CallFinisher& finish) mutable {
                                finish(body(call));
                              });
}

}  // namespace animspace::server
