#include "server/auth.h"

#include <spdlog/spdlog.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>
#include <system_error>

namespace animspace::server {
namespace {

constexpr std::string_view kWhitespace = " \t\r\n\v\f";

std::string_view trim(std::string_view text) {
  const auto first = text.find_first_not_of(kWhitespace);
  if (first == std::string_view::npos) return {};
  const auto last = text.find_last_not_of(kWhitespace);
  return text.substr(first, last - first + 1);
}

std::string quoted(const std::filesystem::path& path) { return "'" + path.string() + "'"; }

// The whole file named by `flag`. Errors: kNotFound (missing), kIo (directory, unreadable).
Result<std::string> read_flag_file(const std::filesystem::path& path, std::string_view flag) {
  const std::string where = std::string(flag) + ": " + quoted(path);
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (status.type() == std::filesystem::file_type::not_found) {
    return make_error(ErrorCode::kNotFound, where + " does not exist");
  }
  if (ec) return make_error(ErrorCode::kIo, where + " cannot be inspected: " + ec.message());
  if (std::filesystem::is_directory(status)) {
    return make_error(ErrorCode::kIo, where + " is a directory, expected a file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return make_error(ErrorCode::kIo, where + " cannot be opened: " + std::strerror(errno));
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return make_error(ErrorCode::kIo, where + " cannot be read: " + std::strerror(errno));
  return text;
}

// What a gRPC text metadata value can carry (printable ASCII), minus the space that separates
// the scheme from the token.
bool is_valid_token(std::string_view token) {
  for (const char c : token) {
    if (c < 0x21 || c > 0x7e) return false;
  }
  return !token.empty();
}

Result<std::vector<std::string>> read_token_file(const std::filesystem::path& path, std::string_view flag) {
  auto text = read_flag_file(path, flag);
  if (!text) return text.error();
  std::vector<std::string> tokens;
  std::istringstream lines(*text);
  std::string line;
  for (int line_number = 1; std::getline(lines, line); ++line_number) {
    const std::string_view token = trim(line);
    if (token.empty() || token.front() == '#') continue;
    if (!is_valid_token(token)) {
      // The offending value is a (possibly mistyped) secret: name the line, never the content.
      return make_error(ErrorCode::kInvalidArgument,
                        std::string(flag) + ": " + quoted(path) + " line " + std::to_string(line_number) +
                            ": a token must be printable ASCII without spaces");
    }
    tokens.emplace_back(token);
  }
  if (tokens.empty()) {
    return make_error(ErrorCode::kInvalidArgument,
                      std::string(flag) + ": " + quoted(path) +
                          " holds no tokens (only blank or '#' lines), which would refuse every call; "
                          "leave " + std::string(flag) + " unset instead");
  }
  return tokens;
}

// The token of one "authorization" value, or nullopt when it is not "Bearer <token>".
std::optional<std::string_view> bearer_token(std::string_view value) {
  constexpr std::string_view kScheme = "bearer";
  if (value.size() <= kScheme.size()) return std::nullopt;
  for (size_t i = 0; i < kScheme.size(); ++i) {
    const char c = value[i];
    if ((c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : c) != kScheme[i]) return std::nullopt;
  }
  if (value[kScheme.size()] != ' ' && value[kScheme.size()] != '\t') return std::nullopt;  // "Bearerx"
  const std::string_view token = trim(value.substr(kScheme.size()));
  if (token.empty()) return std::nullopt;
  return token;
}

// Compares against every entry, without stopping at a match, so that timing does not reveal
// which entry (or how early in the list) a token matched.
bool contains_token(const std::vector<std::string>& tokens, std::string_view candidate) {
  bool found = false;
  for (const auto& token : tokens) {
    if (tokens_equal_constant_time(token, candidate)) found = true;
  }
  return found;
}

bool looks_like_pem_certificate(const std::string& text) {
  return text.find("-----BEGIN CERTIFICATE-----") != std::string::npos;
}

bool looks_like_pem_private_key(const std::string& text) {
  return text.find("-----BEGIN ") != std::string::npos && text.find("PRIVATE KEY-----") != std::string::npos;
}

bool is_encrypted_pem_key(const std::string& text) {
  return text.find("ENCRYPTED PRIVATE KEY") != std::string::npos || text.find("Proc-Type: 4,ENCRYPTED") != std::string::npos;
}

Result<std::string> read_pem_certificates(const std::filesystem::path& path, std::string_view flag) {
  auto text = read_flag_file(path, flag);
  if (!text) return text.error();
  if (!looks_like_pem_certificate(*text)) {
    return make_error(ErrorCode::kInvalidArgument, std::string(flag) + ": " + quoted(path) +
                                                       " is not a PEM certificate (no '-----BEGIN CERTIFICATE-----' line)");
  }
  return text;
}

Result<std::string> read_pem_private_key(const std::filesystem::path& path, std::string_view flag) {
  auto text = read_flag_file(path, flag);
  if (!text) return text.error();
  const std::string where = std::string(flag) + ": " + quoted(path);
  if (!looks_like_pem_private_key(*text)) {
    return make_error(ErrorCode::kInvalidArgument,
                      where + " is not a PEM private key (no '-----BEGIN ... PRIVATE KEY-----' line)");
  }
  // gRPC has no way to ask for a passphrase; it would fail later with a vaguer message.
  if (is_encrypted_pem_key(*text)) {
    return make_error(ErrorCode::kInvalidArgument,
                      where + " is an encrypted private key; give an unencrypted one (openssl pkey -in KEY -out PLAIN)");
  }
  return text;
}

}  // namespace

bool tokens_equal_constant_time(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  // volatile: keeps the compiler from turning the accumulation back into an early-exit compare.
  volatile unsigned char difference = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    difference = difference | static_cast<unsigned char>(a[i] ^ b[i]);
  }
  return difference == 0;
}

Result<Authenticator> Authenticator::from_options(const ServerOptions& options) {
  Authenticator authenticator;
  if (!options.auth_token_file.empty()) {
    auto tokens = read_token_file(options.auth_token_file, "--auth-token-file");
    if (!tokens) return tokens.error();
    authenticator.user_tokens_ = std::move(*tokens);
  }
  if (!options.admin_token_file.empty()) {
    auto tokens = read_token_file(options.admin_token_file, "--admin-token-file");
    if (!tokens) return tokens.error();
    authenticator.admin_tokens_ = std::move(*tokens);
  }
  if (authenticator.enabled() && !tls_enabled(options)) {
    spdlog::warn("bearer tokens are configured without TLS (--tls-cert/--tls-key): they cross the network in "
                 "plaintext");
  }
  return authenticator;
}

grpc::Status Authenticator::check(const std::multimap<grpc::string_ref, grpc::string_ref>& client_metadata,
                                  Access access, std::string_view rpc) const {
  if (access == Access::kPublic) return grpc::Status::OK;
  const bool needs_admin = access == Access::kAdmin && !admin_tokens_.empty();
  if (!needs_admin && user_tokens_.empty()) return grpc::Status::OK;

  // gRPC lower-cases metadata keys on the wire (HTTP/2 header names), so one key suffices.
  bool any_bearer = false;
  bool user = false;
  bool admin = false;
  const auto [begin, end] = client_metadata.equal_range("authorization");
  for (auto entry = begin; entry != end; ++entry) {
    const auto token = bearer_token(std::string_view(entry->second.data(), entry->second.size()));
    if (!token) continue;
    any_bearer = true;
    if (contains_token(admin_tokens_, *token)) admin = true;
    if (contains_token(user_tokens_, *token)) user = true;
  }
  if (!any_bearer) {
    return {grpc::StatusCode::UNAUTHENTICATED, "missing bearer token in 'authorization' metadata"};
  }
  if (!user && !admin) return {grpc::StatusCode::UNAUTHENTICATED, "invalid bearer token"};
  if (needs_admin && !admin) {
    return {grpc::StatusCode::PERMISSION_DENIED, std::string(rpc) + " is an admin RPC: it needs an admin token"};
  }
  return grpc::Status::OK;
}

bool tls_enabled(const ServerOptions& options) { return !options.tls_cert.empty() || !options.tls_key.empty(); }

Result<std::shared_ptr<grpc::ServerCredentials>> make_server_credentials(const ServerOptions& options) {
  const bool has_cert = !options.tls_cert.empty();
  const bool has_key = !options.tls_key.empty();
  if (!has_cert && !has_key) {
    if (!options.tls_client_ca.empty()) {
      return make_error(ErrorCode::kInvalidArgument, "--tls-client-ca: " + quoted(options.tls_client_ca) +
                                                         " given without --tls-cert and --tls-key; client "
                                                         "certificates need TLS");
    }
    return grpc::InsecureServerCredentials();
  }
  if (!has_cert || !has_key) {
    return make_error(ErrorCode::kInvalidArgument,
                      has_cert ? "--tls-cert " + quoted(options.tls_cert) + " given without --tls-key; TLS needs both"
                               : "--tls-key " + quoted(options.tls_key) + " given without --tls-cert; TLS needs both");
  }

  auto cert_chain = read_pem_certificates(options.tls_cert, "--tls-cert");
  if (!cert_chain) return cert_chain.error();
  auto private_key = read_pem_private_key(options.tls_key, "--tls-key");
  if (!private_key) return private_key.error();

  const bool mutual = !options.tls_client_ca.empty();
  grpc::SslServerCredentialsOptions ssl(mutual ? GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY
                                               : GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  ssl.pem_key_cert_pairs.push_back({std::move(*private_key), std::move(*cert_chain)});
  if (mutual) {
    auto client_ca = read_pem_certificates(options.tls_client_ca, "--tls-client-ca");
    if (!client_ca) return client_ca.error();
    ssl.pem_root_certs = std::move(*client_ca);
  }
  auto credentials = grpc::SslServerCredentials(ssl);
  if (!credentials) {
    return make_error(ErrorCode::kInvalidArgument, "--tls-cert/--tls-key: gRPC refused " + quoted(options.tls_cert) +
                                                       " and " + quoted(options.tls_key));
  }
  return credentials;
}

}  // namespace animspace::server
