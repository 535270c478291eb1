// npy.cpp — NumPy .npy float32 arrays: the header is a Python dict literal
// ({'descr': '<f4', 'fortran_order': False, 'shape': (N, M), }), parsed here by a small
// scanner that accepts exactly the literals numpy.save writes (strings, True/False, tuples of
// integers) in any key order.
#include "sdfprune/npy.hpp"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "sdfprune/io.hpp"

namespace sdfprune {
namespace {

constexpr char kMagic[] = "\x93NUMPY";
constexpr size_t kMagicSize = 6;
constexpr size_t kAlign = 64;

static_assert(sizeof(float) == 4);

[[noreturn]] void fail(const std::string& name, const std::string& what) {
    throw IoError(name + ": " + what);
}

// Scanner over the header dict.
class HeaderScanner {
  public:
    HeaderScanner(std::string_view s, const std::string& name) : s_(s), name_(name) {}

    void skip_space() {
        while (i_ < s_.size() &&
               (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\n' || s_[i_] == '\r'))
            ++i_;
    }
    bool at_end() {
        skip_space();
        return i_ >= s_.size();
    }
    bool accept(char c) {
        skip_space();
        if (i_ < s_.size() && s_[i_] == c) {
            ++i_;
            return true;
        }
        return false;
    }
    void expect(char c, const char* where) {
        if (!accept(c)) bad(std::string("expected '") + c + "' " + where);
    }
    std::string string_literal() {
        skip_space();
        if (i_ >= s_.size() || (s_[i_] != '\'' && s_[i_] != '"')) bad("expected a string");
        const char q = s_[i_++];
        const size_t start = i_;
        while (i_ < s_.size() && s_[i_] != q) {
            if (s_[i_] == '\\') bad("escapes in header strings are not supported");
            ++i_;
        }
        if (i_ >= s_.size()) bad("unterminated string");
        return std::string(s_.substr(start, i_++ - start));
    }
    bool peek_string() {
        skip_space();
        return i_ < s_.size() && (s_[i_] == '\'' || s_[i_] == '"');
    }
    bool peek(char c) {
        skip_space();
        return i_ < s_.size() && s_[i_] == c;
    }
    std::string word() {
        skip_space();
        const size_t start = i_;
        while (i_ < s_.size() &&
               (std::isalnum(static_cast<unsigned char>(s_[i_])) || s_[i_] == '_'))
            ++i_;
        if (start == i_) bad("expected a value");
        return std::string(s_.substr(start, i_ - start));
    }
    uint64_t integer() {
        skip_space();
        const size_t start = i_;
        uint64_t v = 0;
        while (i_ < s_.size() && s_[i_] >= '0' && s_[i_] <= '9') {
            const uint64_t d = uint64_t(s_[i_] - '0');
            if (v > (UINT64_MAX - d) / 10) bad("dimension too large");
            v = v * 10 + d;
            ++i_;
        }
        if (start == i_) bad("expected a non-negative integer in 'shape'");
        if (i_ < s_.size() && (s_[i_] == 'L' || s_[i_] == 'l')) ++i_;  // Python 2 longs
        return v;
    }
    [[noreturn]] void bad(const std::string& what) const {
        fail(name_, "malformed .npy header: " + what);
    }

  private:
    std::string_view s_;
    const std::string& name_;
    size_t i_ = 0;
};

void byteswap_if_big_endian(float* v, size_t n) {
    if constexpr (std::endian::native == std::endian::big) {
        for (size_t i = 0; i < n; ++i) {
            uint32_t u;
            std::memcpy(&u, v + i, 4);
            u = __builtin_bswap32(u);
            std::memcpy(v + i, &u, 4);
        }
    } else {
        (void)v;
        (void)n;
    }
}

uint64_t element_count(std::span<const uint64_t> shape, const std::string& name) {
    uint64_t count = 1;
    for (uint64_t d : shape) {
        if (d != 0 && count > UINT64_MAX / 4 / d) fail(name, "array too large");
        count *= d;
    }
    return count;
}

}  // namespace

NpyArray parse_npy(std::string_view bytes, const std::string& name) {
    if (bytes.size() < kMagicSize + 4 || std::memcmp(bytes.data(), kMagic, kMagicSize) != 0)
        fail(name, "not a .npy file (no \\x93NUMPY magic)");
    const auto u8 = [&](size_t at) { return uint32_t(static_cast<unsigned char>(bytes[at])); };
    const uint32_t major = u8(6), minor = u8(7);
    size_t header_len = 0, data_at = 0;
    if (major == 1) {
        header_len = u8(8) | (u8(9) << 8);
        data_at = 10 + header_len;
    } else if (major == 2 || major == 3) {
        if (bytes.size() < 12) fail(name, "truncated .npy header");
        header_len = size_t(u8(8) | (u8(9) << 8) | (u8(10) << 16) | (u8(11) << 24));
        data_at = 12 + header_len;
    } else {
        fail(name, "unsupported .npy format version " + std::to_string(major) + "." +
                       std::to_string(minor));
    }
    if (data_at > bytes.size()) fail(name, "truncated .npy header");
    HeaderScanner sc(bytes.substr(data_at - header_len, header_len), name);

    bool have_descr = false, have_order = false, have_shape = false, fortran = false;
    std::string descr;
    NpyArray a;
    sc.expect('{', "at the start of the header");
    while (!sc.accept('}')) {
        const std::string key = sc.string_literal();
        sc.expect(':', "after a key");
        if (key == "descr") {
            if (!sc.peek_string()) sc.bad("'descr' must be a simple dtype string");
            descr = sc.string_literal();
            have_descr = true;
        } else if (key == "fortran_order") {
            const std::string w = sc.word();
            if (w != "True" && w != "False") sc.bad("'fortran_order' must be True or False");
            fortran = w == "True";
            have_order = true;
        } else if (key == "shape") {
            sc.expect('(', "to open 'shape'");
            while (!sc.accept(')')) {
                a.shape.push_back(sc.integer());
                if (!sc.accept(',') && !sc.peek(')')) sc.bad("expected ',' or ')' in 'shape'");
            }
            have_shape = true;
        } else {
            sc.bad("unexpected key '" + key + "'");
        }
        if (!sc.accept(',') && !sc.peek('}')) sc.bad("expected ',' or '}'");
    }
    if (!sc.at_end()) sc.bad("text after the dict");
    if (!have_descr || !have_order || !have_shape)
        sc.bad("missing 'descr', 'fortran_order' or 'shape'");
    if (descr != "<f4")
        fail(name, "dtype '" + descr + "' is not supported (expected float32 '<f4')");
    uint64_t non_trivial = 0;
    for (uint64_t d : a.shape) non_trivial += d > 1 ? 1 : 0;
    if (fortran && non_trivial > 1)
        fail(name, "Fortran-order arrays are not supported (save with C order)");

    const uint64_t count = element_count(a.shape, name);
    const uint64_t have = bytes.size() - data_at;
    if (have < count * 4)
        fail(name, "truncated: shape needs " + std::to_string(count * 4) +
                       " bytes of data, file has " + std::to_string(have));
    if (have > count * 4)
        fail(name, std::to_string(have - count * 4) + " bytes after the array data");
    a.data.resize(count);
    if (count > 0) std::memcpy(a.data.data(), bytes.data() + data_at, count * 4);
    byteswap_if_big_endian(a.data.data(), a.data.size());
    return a;
}

NpyArray read_npy(const std::string& path) {
    return parse_npy(read_file(path), path);
}

std::string npy_header(std::span<const uint64_t> shape) {
    std::string dict = "{'descr': '<f4', 'fortran_order': False, 'shape': (";
    for (size_t i = 0; i < shape.size(); ++i) {
        dict += std::to_string(shape[i]);
        if (i + 1 < shape.size() || shape.size() == 1) dict += ",";
        if (i + 1 < shape.size()) dict += " ";
    }
    dict += "), }";
    // Version 1.0 has a 2-byte length; 2.0 a 4-byte one.
    size_t prefix = kMagicSize + 2 + 2;
    if (prefix + dict.size() + 1 > 65535) prefix = kMagicSize + 2 + 4;
    const size_t total = (prefix + dict.size() + 1 + kAlign - 1) / kAlign * kAlign;
    const size_t len = total - prefix;
    dict.append(len - dict.size() - 1, ' ');
    dict += '\n';
    std::string h(kMagic, kMagicSize);
    if (prefix == kMagicSize + 4) {
        h += char(1);
        h += char(0);
        h += char(len & 0xff);
        h += char((len >> 8) & 0xff);
    } else {
        h += char(2);
        h += char(0);
        for (int b = 0; b < 4; ++b) h += char((len >> (8 * b)) & 0xff);
    }
    return h + dict;
}

void write_npy(const std::string& path, std::span<const uint64_t> shape,
               std::span<const float> data) {
    uint64_t count = 1;
    for (uint64_t d : shape) count *= d;
    if (count != data.size())
        throw std::invalid_argument("write_npy: data size does not match the shape");
    const std::string header = npy_header(shape);
    write_atomic_with(path, [&](const std::string& tmp) {
        std::FILE* f = std::fopen(tmp.c_str(), "wb");
        if (!f) throw IoError(path + ": cannot create: " + std::strerror(errno));
        bool ok = std::fwrite(header.data(), 1, header.size(), f) == header.size();
        if constexpr (std::endian::native == std::endian::big) {
            std::vector<float> chunk;
            for (size_t i = 0; ok && i < data.size(); i += 65536) {
                chunk.assign(data.begin() + i, data.begin() + std::min(data.size(), i + 65536));
                byteswap_if_big_endian(chunk.data(), chunk.size());
                ok = std::fwrite(chunk.data(), 4, chunk.size(), f) == chunk.size();
            }
        } else if (!data.empty()) {
            ok = ok && std::fwrite(data.data(), 4, data.size(), f) == data.size();
        }
        if (std::fclose(f) != 0 || !ok) throw IoError(path + ": write failed");
    });
}

}  // namespace sdfprune
