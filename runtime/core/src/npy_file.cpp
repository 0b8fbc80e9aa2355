#include "proprio/core/npy_file.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>

#include "proprio/core/file_io.hpp"

namespace proprio {

namespace {

static_assert(std::endian::native == std::endian::little || std::endian::native == std::endian::big,
              "mixed-endian hosts are not supported");

// The header text is padded to this size whatever the row count, so close()
// can rewrite it in place: the magic (6), version (2), length (2) and the
// dict fit in 128 bytes for any shape we write, and 64-byte alignment is what
// numpy itself uses.
constexpr std::size_t kHeaderBytes = 128;

Error io_error(const std::filesystem::path& path, const std::string& what) {
  return make_error(Errc::io_error, "dataset file '" + path.string() + "': " + what);
}

}  // namespace

std::string_view npy_descr(NpyType t) noexcept {
  switch (t) {
    case NpyType::float32: return "<f4";
    case NpyType::int32: return "<i4";
    case NpyType::uint8: return "|u1";
  }
  return "?";
}

std::string NpyWriter::header(std::size_t rows) const {
  std::string shape = "(" + std::to_string(rows) + ",";
  for (std::size_t i = 0; i < row_shape_.size(); ++i) shape += (i ? ", " : " ") + std::to_string(row_shape_[i]);
  shape += ")";
  std::string dict = "{'descr': '" + std::string(npy_descr(type_)) + "', 'fortran_order': False, 'shape': " + shape + ", }";
  // Magic, version 1.0, little-endian header length, then the dict padded
  // with spaces and ended by a newline.
  std::string h = "\x93NUMPY";
  h += '\x01';
  h += '\x00';
  const std::size_t dict_len = kHeaderBytes - 10;
  if (dict.size() + 1 > dict_len) return {};  // does not fit the reserved header
  h += static_cast<char>(dict_len & 0xff);
  h += static_cast<char>((dict_len >> 8) & 0xff);
  dict.resize(dict_len - 1, ' ');
  h += dict;
  h += '\n';
  return h;
}

Result<NpyWriter> NpyWriter::create(const std::filesystem::path& path, NpyType type,
                                    std::vector<std::size_t> row_shape) {
  NpyWriter w;
  w.path_ = path;
  w.type_ = type;
  w.row_shape_ = std::move(row_shape);
  for (auto d : w.row_shape_) w.row_elements_ *= d;
  if (w.row_elements_ == 0) return make_error(Errc::invalid_argument, "an .npy row needs at least one element");
  if (w.header(std::size_t{1} << 62).size() != kHeaderBytes) {
    return make_error(Errc::invalid_argument, "the .npy shape is too long for the reserved header");
  }
  if (auto st = check_output_path(path, "dataset array"); !st) return st.error();
  w.out_ = std::make_unique<std::ofstream>(path, std::ios::binary | std::ios::trunc);
  if (!*w.out_) return io_error(path, "cannot be created; check the folder exists and is writable");
  const std::string h = w.header(0);
  w.out_->write(h.data(), static_cast<std::streamsize>(h.size()));
  if (!*w.out_) return io_error(path, "writing the header failed");
  return w;
}

NpyWriter::~NpyWriter() {
  if (out_) (void)close();
}

Status NpyWriter::append_bytes(const void* data, std::size_t count, std::size_t element_size, NpyType type) {
  if (!out_) return io_error(path_, "is already closed");
  if (type != type_) return make_error(Errc::invalid_argument, "appending the wrong element type to " + path_.string());
  const auto* bytes = static_cast<const char*>(data);
  if constexpr (std::endian::native == std::endian::little) {
    out_->write(bytes, static_cast<std::streamsize>(count * element_size));
  } else {
    std::vector<char> swapped(bytes, bytes + count * element_size);
    for (std::size_t i = 0; i < count; ++i) std::reverse(swapped.begin() + static_cast<std::ptrdiff_t>(i * element_size),
                                                         swapped.begin() + static_cast<std::ptrdiff_t>((i + 1) * element_size));
    out_->write(swapped.data(), static_cast<std::streamsize>(swapped.size()));
  }
  if (!*out_) return io_error(path_, "writing failed (disk full?)");
  pending_elements_ += count;
  rows_ += pending_elements_ / row_elements_;
  pending_elements_ %= row_elements_;
  return {};
}

Status NpyWriter::append(std::span<const float> v) { return append_bytes(v.data(), v.size(), 4, NpyType::float32); }
Status NpyWriter::append(std::span<const std::int32_t> v) { return append_bytes(v.data(), v.size(), 4, NpyType::int32); }
Status NpyWriter::append(std::span<const std::uint8_t> v) { return append_bytes(v.data(), v.size(), 1, NpyType::uint8); }

Status NpyWriter::close() {
  if (!out_) return {};
  auto out = std::move(out_);
  if (pending_elements_ != 0) {
    return make_error(Errc::invalid_argument, path_.string() + ": the data ended part-way through a row (" +
                                                  std::to_string(pending_elements_) + " of " +
                                                  std::to_string(row_elements_) + " values)");
  }
  const std::string h = header(rows_);
  out->seekp(0);
  out->write(h.data(), static_cast<std::streamsize>(h.size()));
  out->flush();
  if (!*out) return io_error(path_, "finishing the header failed");
  return {};
}

Status write_npy(const std::filesystem::path& path, std::span<const float> values, std::vector<std::size_t> shape) {
  if (shape.empty()) return make_error(Errc::invalid_argument, "an .npy array needs a shape");
  std::size_t total = 1;
  for (auto d : shape) total *= d;
  if (total != values.size()) {
    return make_error(Errc::invalid_argument, path.string() + ": shape does not match the number of values");
  }
  // A 1-D array is rows of one element: NpyWriter writes (N,) for an empty row shape.
  std::vector<std::size_t> row_shape(shape.begin() + 1, shape.end());
  auto w = NpyWriter::create(path, NpyType::float32, row_shape);
  if (!w) return w.error();
  if (auto st = w->append(values); !st) return st;
  return w->close();
}

// --- reading ---------------------------------------------------------------------------------------------------

std::size_t NpyArray::row_size() const noexcept {
  std::size_t n = 1;
  for (std::size_t i = 1; i < shape.size(); ++i) n *= shape[i];
  return n;
}

namespace {

Error npy_error(std::string_view name, const std::string& what) {
  return make_error(Errc::invalid_argument, "'" + printable(name) + "' is not a readable .npy array: " + what);
}

// The value text of `key` in numpy's header dict ("{'descr': '<f4', ...}").
std::string_view dict_value(std::string_view dict, std::string_view key) {
  const std::string quoted = "'" + std::string(key) + "'";
  const auto k = dict.find(quoted);
  if (k == std::string_view::npos) return {};
  auto v = dict.find(':', k + quoted.size());
  if (v == std::string_view::npos) return {};
  ++v;
  while (v < dict.size() && dict[v] == ' ') ++v;
  std::size_t end = v;
  if (end < dict.size() && dict[end] == '(') {
    end = dict.find(')', end);
    return end == std::string_view::npos ? std::string_view{} : dict.substr(v, end - v + 1);
  }
  while (end < dict.size() && dict[end] != ',' && dict[end] != '}') ++end;
  return dict.substr(v, end - v);
}

}  // namespace

Result<NpyArray> parse_npy(std::span<const std::uint8_t> bytes, std::string_view name, std::size_t max_elements) {
  if (bytes.size() < 10 || std::memcmp(bytes.data(), "\x93NUMPY", 6) != 0) return npy_error(name, "no NUMPY magic");
  const unsigned major = bytes[6];
  std::size_t header_len = 0, data_at = 0;
  if (major == 1) {
    header_len = bytes[8] | std::size_t{bytes[9]} << 8;
    data_at = 10 + header_len;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) return npy_error(name, "cut short in its header");
    header_len = bytes[8] | std::size_t{bytes[9]} << 8 | std::size_t{bytes[10]} << 16 | std::size_t{bytes[11]} << 24;
    data_at = 12 + header_len;
  } else {
    return npy_error(name, "format version " + std::to_string(major) + " (1, 2 and 3 are known)");
  }
  if (header_len > 1u << 20 || data_at > bytes.size()) return npy_error(name, "cut short in its header");
  const std::string_view dict(reinterpret_cast<const char*>(bytes.data()) + (data_at - header_len), header_len);

  NpyArray a;
  const auto descr = dict_value(dict, "descr");
  std::size_t element = 0;
  if (descr == "'<f4'") {
    a.type = NpyType::float32, element = 4;
  } else if (descr == "'<i4'") {
    a.type = NpyType::int32, element = 4;
  } else if (descr == "'|u1'") {
    a.type = NpyType::uint8, element = 1;
  } else {
    return npy_error(name, "element type " + printable(descr, 20) + " (float32 '<f4', int32 '<i4' and uint8 '|u1' are read)");
  }
  if (dict_value(dict, "fortran_order") != "False") return npy_error(name, "Fortran order is not read; save C order");
  const auto shape = dict_value(dict, "shape");
  if (shape.size() < 2 || shape.front() != '(' || shape.back() != ')') return npy_error(name, "no shape tuple");
  std::size_t count = 1;
  std::size_t i = 1;
  while (i + 1 < shape.size()) {
    while (i + 1 < shape.size() && (shape[i] == ' ' || shape[i] == ',')) ++i;
    if (i + 1 >= shape.size()) break;
    std::size_t d = 0;
    bool digits = false;
    while (i + 1 < shape.size() && shape[i] >= '0' && shape[i] <= '9') {
      if (d > (std::numeric_limits<std::size_t>::max() - 9) / 10) return npy_error(name, "a dimension overflows");
      d = d * 10 + static_cast<std::size_t>(shape[i] - '0');
      digits = true;
      ++i;
    }
    if (!digits) return npy_error(name, "a malformed shape " + printable(shape, 40));
    if (a.shape.size() == 8) return npy_error(name, "more than 8 dimensions");
    if (d != 0 && count > max_elements / d) return npy_error(name, "more than " + std::to_string(max_elements) + " elements");
    count *= d;
    a.shape.push_back(d);
  }
  if (a.shape.empty()) return npy_error(name, "a 0-d array (a scalar); rows are expected");
  const std::size_t available = bytes.size() - data_at;
  if (available != count * element) {
    return npy_error(name, "the shape needs " + std::to_string(count * element) + " data bytes, the file has " +
                               std::to_string(available) + (available < count * element ? " (cut short?)" : ""));
  }
  a.values.resize(count);
  const std::uint8_t* p = bytes.data() + data_at;
  for (std::size_t k = 0; k < count; ++k, p += element) {
    switch (a.type) {
      case NpyType::float32: {
        std::uint32_t u = p[0] | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
        float f;
        std::memcpy(&f, &u, 4);
        a.values[k] = f;
        break;
      }
      case NpyType::int32: {
        const std::uint32_t u = p[0] | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
        a.values[k] = static_cast<std::int32_t>(u);
        break;
      }
      case NpyType::uint8: a.values[k] = p[0]; break;
    }
  }
  return a;
}

Result<NpyArray> read_npy(const std::filesystem::path& path, std::uint64_t max_bytes) {
  auto text = read_input_file(path, "dataset array", max_bytes);
  if (!text) return text.error();
  return parse_npy({reinterpret_cast<const std::uint8_t*>(text->data()), text->size()}, path.string());
}

}  // namespace proprio
