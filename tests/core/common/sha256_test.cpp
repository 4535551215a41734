// SHA-256 against the FIPS 180-2 examples (Appendix B: one block, two blocks, a million 'a's)
// and the empty message's published digest; pieces fed one by one give the whole's digest.
#include "core/common/sha256.h"

#include <cstddef>
#include <span>
#include <string>

#include <gtest/gtest.h>

namespace animspace {
namespace {

TEST(Sha256, TheStandardsExamples) {
  EXPECT_EQ(hex_digest(sha256("abc")), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(hex_digest(sha256("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq")),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(hex_digest(sha256(std::string(1000000, 'a'))),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
  EXPECT_EQ(hex_digest(sha256("")), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

TEST(Sha256, PiecesGiveTheWholesDigest) {
  const std::string message(1000000, 'a');
  Sha256 digest;
  for (size_t at = 0; at < message.size(); at += 777) {
    const std::string_view piece = std::string_view(message).substr(at, 777);
    digest.update(std::as_bytes(std::span<const char>(piece.data(), piece.size())));
  }
  digest.update({});
  EXPECT_EQ(digest.digest(), sha256(message));
}

}  // namespace
}  // namespace animspace
