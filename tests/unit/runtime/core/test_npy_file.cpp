#include "proprio/core/npy_file.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <vector>

namespace proprio {
namespace {

std::vector<char> read_all(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(NpyFile, RowsAppendedInPiecesGiveTheFinalShapeAndData) {
  const auto path = std::filesystem::path(testing::TempDir()) / "npy_rows.npy";
  auto w = NpyWriter::create(path, NpyType::float32, {2, 3});
  ASSERT_TRUE(w) << w.error().message;
  const std::vector<float> a = {1, 2, 3, 4}, b = {5, 6, 7, 8, 9, 10, 11, 12};
  ASSERT_TRUE(w->append(a));
  ASSERT_TRUE(w->append(b));
  ASSERT_TRUE(w->close());
  EXPECT_EQ(w->rows(), 2u);
  const auto bytes = read_all(path);
  ASSERT_EQ(bytes.size(), 128u + 12 * 4);  // fixed 128-byte header, then the data
  EXPECT_EQ(std::string(bytes.data(), 6), "\x93NUMPY");
  const std::string header(bytes.data() + 10, 118);
  EXPECT_NE(header.find("'descr': '<f4'"), std::string::npos) << header;
  EXPECT_NE(header.find("'shape': (2, 2, 3)"), std::string::npos) << header;
  EXPECT_EQ(header.back(), '\n');
  float last = 0;
  std::memcpy(&last, bytes.data() + 128 + 11 * 4, 4);
  EXPECT_EQ(last, 12.0f);
}

TEST(NpyFile, WrongElementTypeAndEmptyRowsAreRefused) {
  const auto path = std::filesystem::path(testing::TempDir()) / "npy_types.npy";
  auto w = NpyWriter::create(path, NpyType::int32, {});
  ASSERT_TRUE(w);
  const std::vector<float> f = {1.0f};
  EXPECT_FALSE(w->append(f));
  const std::vector<std::int32_t> i = {7, 8};
  EXPECT_TRUE(w->append(i));
  ASSERT_TRUE(w->close());
  EXPECT_NE(std::string(read_all(path).data() + 10, 118).find("'shape': (2,)"), std::string::npos);
  EXPECT_FALSE(NpyWriter::create(path, NpyType::float32, {0, 3}));
  EXPECT_FALSE(write_npy(path, f, {}));
}

}  // namespace
}  // namespace proprio

namespace proprio {
namespace {

TEST(NpyFile, WhatTheWriterWritesReadsBack) {
  const auto path = std::filesystem::path(testing::TempDir()) / "npy_back.npy";
  const std::vector<float> v = {0.5f, -2.0f, 3.25f, 1e-3f, 7.0f, 8.0f};
  ASSERT_TRUE(write_npy(path, v, {3, 2}));
  auto a = read_npy(path);
  ASSERT_TRUE(a) << a.error().message;
  EXPECT_EQ(a->shape, (std::vector<std::size_t>{3, 2}));
  EXPECT_EQ(a->rows(), 3u);
  EXPECT_EQ(a->row_size(), 2u);
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(a->values[i], v[i]);
}

TEST(NpyFile, HostileBytesAreRefusedWithAReason) {
  const auto path = std::filesystem::path(testing::TempDir()) / "npy_hostile.npy";
  const std::vector<float> v = {1, 2, 3, 4};
  ASSERT_TRUE(write_npy(path, v, {4}));
  std::ifstream in(path, std::ios::binary);
  std::vector<std::uint8_t> good{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  ASSERT_TRUE(parse_npy(good, "good"));

  auto cut = good;
  cut.pop_back();
  auto r = parse_npy(cut, "cut");
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("cut short"), std::string::npos) << r.error().message;

  auto bad_type = good;
  const std::string h(bad_type.begin(), bad_type.begin() + 128);
  const auto at = h.find("<f4");
  ASSERT_NE(at, std::string::npos);
  bad_type[at + 1] = 'c';  // complex
  EXPECT_FALSE(parse_npy(bad_type, "complex"));

  auto huge = good;
  const auto s = h.find("(4,)");
  ASSERT_NE(s, std::string::npos);
  const std::string big = "(99999999999999999999,)";
  std::vector<std::uint8_t> header(huge.begin(), huge.begin() + 128);
  std::string hs(header.begin(), header.end());
  hs.replace(s, 4, big);
  hs.erase(hs.size() - 1 - (big.size() - 4), big.size() - 4);  // keep the length
  std::copy(hs.begin(), hs.end(), huge.begin());
  EXPECT_FALSE(parse_npy(huge, "huge"));

  EXPECT_FALSE(parse_npy({}, "empty"));
  EXPECT_FALSE(read_npy("/dev/zero"));
}

}  // namespace
}  // namespace proprio
