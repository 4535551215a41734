// The one path every unary RPC takes: parse the request, authenticate, admit, run the handler
// body on a pool the server owns, record the outcome, serialise the response, finish. Handlers
// only validate and compute.
//
//   return serve_unary<v1::EvaluateKeyPointsRequest, v1::EvaluateKeyPointsResponse>(
//       env_, {context, request, response}, "PoseService/EvaluateKeyPoints", Access::kUser, env_.request_pool,
//       [=](const CallControl& call, const v1::EvaluateKeyPointsRequest* request,
//           v1::EvaluateKeyPointsResponse* response) { …; return grpc::Status::OK; });
//
// Methods are registered raw (server/raw_messages.h): the request arrives as bytes, and bytes that
// are not the RPC's message are answered INVALID_ARGUMENT naming it. They are parsed first, on
// gRPC's thread, as the generated handler did, so that the access an RPC needs may depend on
// its request (GetStats with reset is an admin call).
//
// Deadlines and cancellation: a call whose deadline passed or whose client went away while it
// waited in the queue is never started; long bodies poll `call.stop_status()` between units of
// work (poses of a batch, stages of a retrain) and return it.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>

#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>

#include "server/call_scope.h"
#include "server/raw_messages.h"
#include "server/service_environment.h"
#include "server/status_mapping.h"

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

// A unary call as gRPC hands it to a raw method: its context, and its request and response as
// bytes (both owned by gRPC until the call is done).
struct UnaryBytes {
  grpc::CallbackServerContext* context;
  const grpc::ByteBuffer* request;
  grpc::ByteBuffer* response;
};

// Finishes a deferred call exactly once, from any thread: records the outcome, frees the
// admission slot, serialises the response of a call that succeeded and answers the client.
class CallFinisher {
 public:
  CallFinisher(grpc::ServerUnaryReactor* reactor, std::shared_ptr<CallScope> scope,
               std::shared_ptr<Admission::Ticket> ticket, std::shared_ptr<const google::protobuf::Message> response,
               grpc::ByteBuffer* response_bytes)
      : reactor_(reactor),
        scope_(std::move(scope)),
        ticket_(std::move(ticket)),
        response_(std::move(response)),
        response_bytes_(response_bytes) {}
  void operator()(grpc::Status status) const {
    ticket_->release();
    if (status.ok()) status = serialize_message(*response_, *response_bytes_);
    reactor_->Finish(scope_->finish(std::move(status)));
  }

 private:
  grpc::ServerUnaryReactor* reactor_;
  std::shared_ptr<CallScope> scope_;
  std::shared_ptr<Admission::Ticket> ticket_;
  std::shared_ptr<const google::protobuf::Message> response_;  // keeps the call's messages alive
  grpc::ByteBuffer* response_bytes_;
};

// The access a call needs: `rule` itself, or rule(request) when the request decides.
template <typename Request, typename AccessRule>
Access access_for(const AccessRule& rule, const Request& request) {
  if constexpr (std::is_invocable_r_v<Access, const AccessRule&, const Request&>) {
    return rule(request);
  } else {
    return rule;
  }
}

// For bodies that hand the rest of their work to another thread (the render thread): the body
// runs on `pool` as in serve_unary, as body(call, request, response, finish), and must make
// `finish(status)` happen exactly once — itself, or later from wherever the work ends. `request`
// and `response` live until then. When `here` says so for a request, the body runs at once on
// the gRPC thread that received it instead: for work smaller than the hand-off to the pool and
// back (answers as coordinates: microseconds per pose).
template <typename Request, typename Response, typename AccessRule, typename Body>
grpc::ServerUnaryReactor* serve_unary_deferred(ServiceEnvironment& env, UnaryBytes bytes, const char* rpc,
                                               AccessRule access, WorkPool& pool, Body body,
                                               bool (*here)(const Request&) = nullptr) {
  grpc::CallbackServerContext* context = bytes.context;
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  auto scope = std::make_shared<CallScope>(env.metrics, rpc);
  struct Messages {
    Request request;
    Response response;
  };
  auto messages = std::make_shared<Messages>();
  if (grpc::Status unread = parse_message(*bytes.request, "the request", messages->request); !unread.ok()) {
    reactor->Finish(scope->finish(std::move(unread)));
    return reactor;
  }
  std::shared_ptr<Admission::Ticket> ticket;
  if (grpc::Status refused = admit(env, context, rpc, access_for(access, messages->request), &ticket); !refused.ok()) {
    reactor->Finish(scope->finish(refused));
    return reactor;
  }
  const CallFinisher finish(reactor, scope, ticket,
                            std::shared_ptr<const google::protobuf::Message>(messages, &messages->response),
                            bytes.response);
  if (here != nullptr && here(messages->request)) {
    const CallControl call(context, scope.get());
    body(call, &messages->request, &messages->response, finish);
    return reactor;
  }
  const bool queued = pool.submit([context, scope, finish, messages, body = std::move(body)]() mutable {
    const CallControl call(context, scope.get());
    if (grpc::Status stop = call.stop_status(); !stop.ok()) {
      finish(std::move(stop));
      return;
    }
    body(call, &messages->request, &messages->response, finish);
  });
  if (!queued) finish(unavailable("the server is shutting down"));
  return reactor;
}

// body(call, request, response) returns the call's status; `here` as in serve_unary_deferred.
template <typename Request, typename Response, typename AccessRule, typename Body>
grpc::ServerUnaryReactor* serve_unary(ServiceEnvironment& env, UnaryBytes bytes, const char* rpc, AccessRule access,
                                      WorkPool& pool, Body body, bool (*here)(const Request&) = nullptr) {
  return serve_unary_deferred<Request, Response>(
      env, bytes, rpc, access, pool,
      [body = std::move(body)](const CallControl& call, const Request* request, Response* response,
                               const CallFinisher& finish) mutable { finish(body(call, request, response)); },
      here);
}

}  // namespace animspace::server
