#pragma once
// NumPy .npy files (NPY format 1.0: magic, a header dict, little-endian data),
// written here so that Python reads datasets with numpy.load and nothing
// else. Shared by every dataset writer (the stretch glove's, the stretch
// arrays').
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "proprio/core/result.hpp"

namespace proprio {

enum class NpyType : std::uint8_t { float32, int32, uint8 };
std::string_view npy_descr(NpyType t) noexcept;  // "<f4", "<i4", "|u1"

// An .npy file whose first dimension grows as rows are appended; close()
// writes the final row count into the header (reserved at a fixed size).
class NpyWriter {
 public:
  static Result<NpyWriter> create(const std::filesystem::path& path, NpyType type,
                                  std::vector<std::size_t> row_shape);
  Status append(std::span<const float> values);
  Status append(std::span<const std::int32_t> values);
  Status append(std::span<const std::uint8_t> values);
  Status close();
  std::size_t rows() const noexcept { return rows_; }
  const std::filesystem::path& path() const noexcept { return path_; }

  NpyWriter(NpyWriter&&) = default;
  NpyWriter& operator=(NpyWriter&&) = default;
  ~NpyWriter();

 private:
  NpyWriter() = default;
  Status append_bytes(const void* data, std::size_t count, std::size_t element_size, NpyType type);
  std::string header(std::size_t rows) const;

  std::filesystem::path path_;
  std::unique_ptr<std::ofstream> out_;
  NpyType type_ = NpyType::float32;
  std::vector<std::size_t> row_shape_;
  std::size_t row_elements_ = 1;
  std::size_t rows_ = 0;
  std::size_t pending_elements_ = 0;  // appended elements not yet making a whole row
};

// A whole .npy file at once.
Status write_npy(const std::filesystem::path& path, std::span<const float> values, std::vector<std::size_t> shape);

// An .npy array read back (what NpyWriter writes, and numpy's own C-order
// little-endian float32 / int32 / uint8 files). Values are widened to double
// so that a reader handles every element type alike.
struct NpyArray {
  NpyType type = NpyType::float32;
  std::vector<std::size_t> shape;  // shape[0] is the row count
  std::vector<double> values;      // row-major
  std::size_t rows() const noexcept { return shape.empty() ? 0 : shape[0]; }
  // Elements per row (1 for a 1-D array).
  std::size_t row_size() const noexcept;
};

// Parses a whole .npy file held in memory. Refuses (with what and where):
// a bad magic or version, a header dict that is not numpy's, an element type
// other than <f4 / <i4 / |u1, Fortran order, a shape whose element count
// overflows or disagrees with the bytes present, more than max_elements.
// `name` is used in messages.
Result<NpyArray> parse_npy(std::span<const std::uint8_t> bytes, std::string_view name,
                           std::size_t max_elements = std::size_t{1} << 28);
// Reads and parses a regular file (through read_input_file, capped at max_bytes).
Result<NpyArray> read_npy(const std::filesystem::path& path, std::uint64_t max_bytes = std::uint64_t{2} << 30);

}  // namespace proprio
