// SHA-256 (FIPS 180-4) through OpenSSL's libcrypto: what names a served basis so that a copy
// cached on a client's disk is checked against the server's word, not against a CRC anyone
// can forge (issue #54 item 8).
#pragma once

#include <memory>
#include <span>
#include <string>
#include <string_view>

namespace animspace {

// A digest fed in pieces. digest() ends it: 32 raw bytes.
class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;

  void update(std::span<const std::byte> bytes);
  std::string digest();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// The digest of `bytes` in one call (32 raw bytes), and any digest as lowercase hexadecimal.
std::string sha256(std::string_view bytes);
std::string hex_digest(std::string_view digest);

}  // namespace animspace
