// Messages as bytes. Every animspace.v1 method is registered raw (the services derive from the
// generated WithRawCallbackMethod_* classes) and parses its requests here: gRPC's generated
// handlers answer bytes that are not the method's message with UNIMPLEMENTED and no message
// (grpcpp/impl/codegen/server_callback_handlers.h, 1.51), and a bidi stream's read of such bytes
// simply reports "no more messages". Parsing and serialising are gRPC's own
// (SerializationTraits), so every parsable request is read exactly as the typed handler read it.
#pragma once

#include <string_view>

#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/codegen/proto_utils.h>
#include <grpcpp/support/byte_buffer.h>

#include "server/status_mapping.h"

namespace animspace::server {

// OK with `out` filled, or INVALID_ARGUMENT "<what> could not be parsed as animspace.v1.<Type>".
// `what` names the bytes: "the request", "stream message 3".
template <typename Message>
grpc::Status parse_message(const grpc::ByteBuffer& bytes, std::string_view what, Message& out) {
  // No buffer is zero bytes: the encoding of the default message.
  if (!bytes.Valid()) {
    out.Clear();
    return grpc::Status::OK;
  }
  grpc::ByteBuffer copy(bytes);  // shares the slices; Deserialize consumes its buffer
  if (!grpc::SerializationTraits<Message>::Deserialize(&copy, &out).ok()) {
    return unparsable(what, Message::descriptor()->full_name());
  }
  return grpc::Status::OK;
}

// `message` as bytes to write. INTERNAL only for a message protobuf cannot encode (over 2 GiB).
template <typename Message>
grpc::Status serialize_message(const Message& message, grpc::ByteBuffer& out) {
  bool own_buffer = false;
  grpc::Status status = grpc::SerializationTraits<Message>::Serialize(message, &out, &own_buffer);
  if (!status.ok()) return {grpc::StatusCode::INTERNAL, "cannot encode the response: " + status.error_message()};
  return grpc::Status::OK;
}

}  // namespace animspace::server
