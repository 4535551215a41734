#include "core/mesh_io/text_io.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include <gtest/gtest.h>

namespace animspace::mesh_io {
namespace {

TEST(MeshIoTextReader, WalksLinesAndTokens) {
  TextReader in("a  b\t c\r\n\n  d", "t.txt");
  ASSERT_TRUE(in.next_line());
  EXPECT_EQ(in.line_number(), 1);
  EXPECT_EQ(in.next_token(), "a");
  EXPECT_EQ(in.next_token(), "b");
  EXPECT_EQ(in.next_token(), "c");
  EXPECT_EQ(in.next_token(), "");
  EXPECT_EQ(in.next_token_any_line(), "d");  // skips the empty line 2
  EXPECT_EQ(in.line_number(), 3);
  EXPECT_EQ(in.next_token_any_line(), "");
  EXPECT_FALSE(in.next_line());
}

TEST(MeshIoTextReader, RestAfterLineIsTheBytesPastTheNewline) {
  TextReader in(std::string_view("0 0\n\x01\x02", 6), "t.bin");
  ASSERT_TRUE(in.next_line());
  EXPECT_EQ(in.rest_after_line(), std::string_view("\x01\x02", 2));
}

TEST(MeshIoTextReader, ParsesWholeTokensOnly) {
  const TextReader in("", "t.txt");
  EXPECT_EQ(*in.parse<double>("+2.5", "x"), 2.5);
  EXPECT_EQ(*in.parse<float>("-1e-3", "x"), -1e-3f);
  EXPECT_EQ(*in.parse<int>("+7", "x"), 7);
  EXPECT_EQ(*in.parse<int>("-12", "x"), -12);
  for (const char* bad : {"", "1.5x", "0x10", "+-1", "++1", "nan", "-inf", "infinity", "1e400", "-"}) {
    EXPECT_FALSE(in.parse<double>(bad, "x").ok()) << bad;
  }
  EXPECT_FALSE(in.parse<int>("1.0", "x").ok());
  EXPECT_FALSE(in.parse<int>("3000000000", "x").ok());
  EXPECT_FALSE(in.parse<float>("1e39", "x").ok());
}

TEST(MeshIoTextReader, ValuesBelowTheSmallestSubnormalRoundToSignedZero) {
  const TextReader in("", "t.txt");
  const auto tiny = in.parse<float>("-1e-50", "x");
  ASSERT_TRUE(tiny.ok());
  EXPECT_EQ(*tiny, 0.0f);
  EXPECT_TRUE(std::signbit(*tiny));
  EXPECT_EQ(*in.parse<double>("1e-400", "x"), 0.0);
  EXPECT_EQ(*in.parse<float>("1e-40", "x"), 1e-40f);  // subnormal, kept
}

TEST(MeshIoTextReader, ErrorsNameSourceLineExpectedAndFound) {
  TextReader in("first\nsecond", "dir/file.txt");
  ASSERT_TRUE(in.next_line());
  ASSERT_TRUE(in.next_line());
  const auto value = in.read<double>("a weight");
  ASSERT_FALSE(value.ok());
  EXPECT_EQ(value.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(value.error().message, "dir/file.txt:2: expected a weight, got 'second'");
  EXPECT_EQ(in.read<int>("a count").error().message, "dir/file.txt:2: expected a count, got end of line");
  const std::string long_token(100, 'z');
  EXPECT_EQ(in.error("a number", long_token).message,
            "dir/file.txt:2: expected a number, got '" + std::string(40, 'z') + "...'");
}

TEST(MeshIoTextReader, AppendNumberRoundTripsExactly) {
  const TextReader in("", "t.txt");
  for (const float value : {0.1f, -1.0f / 3.0f, std::numeric_limits<float>::denorm_min(),
                            std::numeric_limits<float>::max(), 16777217.0f, -0.0f}) {
    std::string text;
    append_number(text, value);
    EXPECT_EQ(std::bit_cast<uint32_t>(*in.parse<float>(text, "x")), std::bit_cast<uint32_t>(value)) << text;
  }
  for (const double value : {0.1, 1.0 / 3.0, 1e-310, std::numeric_limits<double>::max(), -0.0}) {
    std::string text;
    append_number(text, value);
    EXPECT_EQ(std::bit_cast<uint64_t>(*in.parse<double>(text, "x")), std::bit_cast<uint64_t>(value)) << text;
  }
  std::string text;
  append_number(text, -42);
  EXPECT_EQ(text, "-42");
}

TEST(MeshIoTextReader, LowercaseExtension) {
  EXPECT_EQ(lowercase_extension("a/b/Mesh.OBJ"), ".obj");
  EXPECT_EQ(lowercase_extension("noext"), "");
}

}  // namespace
}  // namespace animspace::mesh_io
