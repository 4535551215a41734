// Throw-away certificates for TLS tests, made at run time with the `openssl` command (Debian
// package `openssl`, installed by scripts/install-deps.sh). Header-only so that any test
// executable can use it without a build change.
//
// EC P-256 keys: generating them takes milliseconds, so a suite can make a fresh set each run
// (about 0.1 s for the whole set) instead of checking in keys that expire.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <stdexcept>
#include <string>

namespace animspace::testing {

struct TlsFiles {
  std::filesystem::path ca_cert;        // self-signed CA that signed server_cert and client_cert
  std::filesystem::path server_cert;    // CN=localhost, subjectAltName DNS:localhost, IP:127.0.0.1
  std::filesystem::path server_key;
  std::filesystem::path client_cert;    // CN=animspace test client, extendedKeyUsage clientAuth
  std::filesystem::path client_key;
  std::filesystem::path other_ca_cert;  // an unrelated self-signed CA (trusts nothing above)
  std::filesystem::path other_ca_key;   // its key: other_ca_cert doubles as a client certificate
                                        // that does not chain to ca_cert
};

// The whole content of a text file; throws std::runtime_error when it cannot be read.
inline std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path.string());
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

namespace tls_detail {

inline std::string shell_quote(const std::string& text) {
  std::string quoted = "'";
  for (const char c : text) {
    if (c == '\'') {
      quoted += "'\\''";
    } else {
      quoted += c;
    }
  }
  return quoted + "'";
}

// Extensions for the certificates; a config of our own keeps the result independent of the
// system's openssl.cnf (whose req -x509 defaults differ between OpenSSL versions).
constexpr const char* kOpensslConfig = R"(# written by tests/support/tls_fixtures.h
[req]
distinguished_name = dn
prompt = no
[dn]
CN = unused
[ca]
basicConstraints = critical, CA:TRUE
keyUsage = critical, keyCertSign, cRLSign
subjectKeyIdentifier = hash
[server]
basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = serverAuth
subjectAltName = DNS:localhost, IP:127.0.0.1
authorityKeyIdentifier = keyid
[client]
basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = clientAuth
authorityKeyIdentifier = keyid
)";

}  // namespace tls_detail

// Whether the `openssl` command can be run.
inline bool openssl_available() { return std::system("openssl version >/dev/null 2>&1") == 0; }

// Generates, into `dir` (which must exist), a CA, a server certificate for "localhost" signed by
// it, a client certificate signed by it, and an unrelated second CA; all valid for two days.
// Returns nullopt and sets *why_not (may be null) when openssl is missing or one of its commands
// fails (then with openssl's own output). Tests skip when !openssl_available() and fail otherwise.
inline std::optional<TlsFiles> make_tls_files(const std::filesystem::path& dir, std::string* why_not) {
  using tls_detail::shell_quote;
  auto fail = [why_not](const std::string& why) -> std::optional<TlsFiles> {
    if (why_not) *why_not = why;
    return std::nullopt;
  };
  if (!openssl_available()) {
    return fail("the `openssl` command is not available (scripts/install-deps.sh installs package openssl)");
  }

  const auto config = dir / "openssl.cnf";
  const auto log = dir / "openssl.log";
  {
    std::ofstream out(config, std::ios::binary);
    out << tls_detail::kOpensslConfig;
    if (!out) return fail("cannot write " + config.string());
  }
  auto path = [&dir](const char* name) { return shell_quote((dir / name).string()); };
  const std::string new_ec_key =
      " -config " + shell_quote(config.string()) + " -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes";
  auto run = [&](const std::string& arguments) {
    const std::string command = "openssl " + arguments + " >" + shell_quote(log.string()) + " 2>&1";
    if (std::system(command.c_str()) == 0) return true;
    std::string output;
    try {
      output = read_text(log);
    } catch (const std::exception&) {
    }
    if (why_not) *why_not = "`" + command + "` failed: " + output;
    return false;
  };
  auto make_ca = [&](const char* stem, const char* common_name) {
    return run("req -x509 -days 2 -extensions ca -subj " + shell_quote(std::string("/CN=") + common_name) +
               new_ec_key + " -keyout " + path((std::string(stem) + ".key").c_str()) + " -out " +
               path((std::string(stem) + ".pem").c_str()));
  };
  // A key and request for `stem`, then the certificate signed by ca.pem with `extensions`.
  auto make_leaf = [&](const char* stem, const char* common_name, const char* extensions, int serial) {
    const std::string s(stem);
    return run("req -new -subj " + shell_quote(std::string("/CN=") + common_name) + new_ec_key + " -keyout " +
               path((s + ".key").c_str()) + " -out " + path((s + ".csr").c_str())) &&
           run("x509 -req -days 2 -set_serial " + std::to_string(serial) + " -in " + path((s + ".csr").c_str()) +
               " -CA " + path("ca.pem") + " -CAkey " + path("ca.key") + " -extfile " +
               shell_quote(config.string()) + " -extensions " + extensions + " -out " + path((s + ".pem").c_str()));
  };
  if (!make_ca("ca", "animspace test CA") || !make_ca("other_ca", "animspace unrelated CA") ||
      !make_leaf("server", "localhost", "server", 2) ||
      !make_leaf("client", "animspace test client", "client", 3)) {
    return std::nullopt;
  }
  return TlsFiles{dir / "ca.pem",     dir / "server.pem",   dir / "server.key", dir / "client.pem",
                  dir / "client.key", dir / "other_ca.pem", dir / "other_ca.key"};
}

}  // namespace animspace::testing
