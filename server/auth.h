// Who may talk to the daemon: TLS server credentials from PEM files (transport), and bearer
// tokens checked per call (caller), with a separate, stronger token set for admin RPCs.
//
// The daemon builds both once at start-up from ServerOptions; a configuration mistake is an
// Error naming the flag and the path (the daemon logs it and exits) rather than a server that
// silently accepts everyone or no one. RPC handlers call Authenticator::check() first thing.
#pragma once

#include <grpcpp/security/server_credentials.h>
#include <grpcpp/support/status.h>
#include <grpcpp/support/string_ref.h>

#include <cstddef>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/result.h"
#include "server/options.h"

namespace animspace::server {

// What an RPC requires of its caller.
enum class Access {
  kPublic,  // no token (health, reflection): probes and tooling must work without secrets
  kUser,    // any configured token, user or admin
  kAdmin,   // an admin token when admin tokens are configured; otherwise as kUser
};

// Bearer-token check for the "authorization: Bearer <token>" metadata (RFC 6750 §2.1) that
// grpc::AccessTokenCredentials and most gRPC clients send.
//
// Token files (--auth-token-file, --admin-token-file): one token per line; surrounding
// whitespace is trimmed; blank lines and lines starting with '#' are ignored; a token is
// printable ASCII without spaces (what a gRPC text metadata value can carry). Token values are
// never logged or put into messages.
class Authenticator {
 public:
  // No tokens: every check passes.
  Authenticator() = default;

  // Reads options.auth_token_file and options.admin_token_file (each optional).
  // Errors, each naming the flag and the path: kNotFound (file missing), kIo (unreadable),
  // kInvalidArgument (a file with no tokens — it would lock everyone out silently — or a line
  // that is not a valid token, by line number).
  static Result<Authenticator> from_options(const ServerOptions& options);

  // Whether any token is configured at all.
  bool enabled() const { return !user_tokens_.empty() || !admin_tokens_.empty(); }
  size_t user_token_count() const { return user_tokens_.size(); }
  size_t admin_token_count() const { return admin_tokens_.size(); }

  // Checks a call's client metadata (ServerContext::client_metadata()) for `access`.
  // The scheme "Bearer" is matched case-insensitively (RFC 7235 §2.1); when several
  // "authorization" entries are present the most privileged valid one counts.
  // kUser passes when no user tokens are configured; otherwise it needs a user or admin token.
  // kAdmin needs an admin token when admin tokens are configured; otherwise it is kUser.
  // Returns OK, UNAUTHENTICATED ("missing bearer token in 'authorization' metadata" or
  // "invalid bearer token") or PERMISSION_DENIED ("<rpc> is an admin RPC: it needs an admin
  // token"), where `rpc` is the full method name ("/animspace.v1.ModelService/LoadModel").
  grpc::Status check(const std::multimap<grpc::string_ref, grpc::string_ref>& client_metadata,
                     Access access, std::string_view rpc) const;

 private:
  std::vector<std::string> user_tokens_;
  std::vector<std::string> admin_tokens_;
};

// Token comparison whose running time does not depend on where two equal-length strings first
// differ, so response timing cannot be used to guess a token byte by byte. Strings of different
// lengths return false at once: the length leaks, which is acceptable because it says nothing
// about the content of a random token of any useful length.
bool tokens_equal_constant_time(std::string_view a, std::string_view b);

// Whether the options ask for TLS (--tls-cert or --tls-key given; make_server_credentials
// refuses a half configuration).
bool tls_enabled(const ServerOptions& options);

// Server credentials for ServerBuilder::AddListeningPort.
// tls_cert and tls_key both empty: plaintext (grpc::InsecureServerCredentials).
// Both given: TLS with that certificate chain and private key (PEM, unencrypted key).
// tls_client_ca also given: mutual TLS — every client must present a certificate that chains to
// that CA bundle (GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY).
// Errors naming the flag and the path: kInvalidArgument when only one of --tls-cert/--tls-key is
// given, when --tls-client-ca is given without them, or when a file does not look like the PEM it
// should be; kNotFound / kIo when a file is missing / unreadable. A certificate that is PEM but
// does not match its key is only detected by gRPC when the port is added (BuildAndStart fails).
Result<std::shared_ptr<grpc::ServerCredentials>> make_server_credentials(const ServerOptions& options);

}  // namespace animspace::server
