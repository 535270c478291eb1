// npy.hpp — a minimal reader and writer of NumPy .npy files (format versions 1.0, 2.0 and 3.0,
// https://numpy.org/doc/stable/reference/generated/numpy.lib.format.html) for the one array
// type sdfprune exchanges: float32, little-endian ('<f4'), C order.
//
// Writing emits version 1.0 (2.0 when the header does not fit 64 KiB), header padded so the data
// starts at a multiple of 64 bytes, as numpy.save does. Reading accepts what numpy.save writes
// for such arrays and refuses anything else with an IoError whose one-line message names the
// file and the problem: not a .npy file, another dtype ('<f8', '>f4', ...), fortran_order True
// for arrays of two or more dimensions, a malformed header, a data size that does not match the
// shape (truncated or trailing bytes).
//
// Thread-safety: pure functions; no shared state.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace sdfprune {

struct NpyArray {
    std::vector<uint64_t> shape;  // () for a scalar
    std::vector<float> data;      // product(shape) values, C order
};

// Parses a whole .npy file held in memory; `name` is used in messages.
NpyArray parse_npy(std::string_view bytes, const std::string& name);
// Reads a .npy file (IoError if it cannot be read or is not a float32 C-order array).
NpyArray read_npy(const std::string& path);

// The header (magic, version, length, padded dict) of a float32 C-order array of `shape`.
std::string npy_header(std::span<const uint64_t> shape);
// Writes `data` (product(shape) values, C order) to `path` atomically (io.hpp): no partial
// file on failure. Throws std::invalid_argument if data.size() does not match the shape and
// IoError if the file cannot be written.
void write_npy(const std::string& path, std::span<const uint64_t> shape,
               std::span<const float> data);

}  // namespace sdfprune
