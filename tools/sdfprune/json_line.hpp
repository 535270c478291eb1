// json_line.hpp — builds the one JSON object a subcommand prints as its last stdout line.
#pragma once

#include <cmath>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

#include "sdfprune/scene.hpp"

namespace sdfprune::cli {

class JsonLine {
  public:
    JsonLine& add(std::string_view key, double v) {
        key_(key);
        if (!std::isfinite(v)) {
            s_ += "null";
            return *this;
        }
        char buf[40];
        std::snprintf(buf, sizeof buf, "%.9g", v);
        s_ += buf;
        return *this;
    }
    // Integers exactly (byte counts pass 10^9, where "%.9g" would round them).
    JsonLine& add(std::string_view key, int v) { return integer_(key, std::to_string(v)); }
    JsonLine& add(std::string_view key, uint32_t v) { return integer_(key, std::to_string(v)); }
    JsonLine& add(std::string_view key, uint64_t v) { return integer_(key, std::to_string(v)); }
    JsonLine& add(std::string_view key, bool v) {
        key_(key);
        s_ += v ? "true" : "false";
        return *this;
    }
    JsonLine& add(std::string_view key, std::string_view v) {
        key_(key);
        quote_(v);
        return *this;
    }
    JsonLine& add(std::string_view key, const char* v) { return add(key, std::string_view(v)); }
    JsonLine& add(std::string_view key, vec3 v) {
        key_(key);
        char buf[96];
        std::snprintf(buf, sizeof buf, "[%.9g,%.9g,%.9g]", v.x, v.y, v.z);
        s_ += buf;
        return *this;
    }
    // A nested object, given as a finished JsonLine.
    JsonLine& add(std::string_view key, const JsonLine& obj) {
        key_(key);
        s_ += obj.str();
        return *this;
    }
    // An array of nested objects.
    JsonLine& add(std::string_view key, const std::vector<JsonLine>& objs) {
        key_(key);
        s_ += "[";
        for (size_t i = 0; i < objs.size(); ++i) s_ += (i ? "," : "") + objs[i].str();
        s_ += "]";
        return *this;
    }
    std::string str() const { return "{" + s_ + "}"; }

  private:
    JsonLine& integer_(std::string_view key, const std::string& digits) {
        key_(key);
        s_ += digits;
        return *this;
    }
    void key_(std::string_view k) {
        if (!s_.empty()) s_ += ",";
        quote_(k);
        s_ += ":";
    }
    void quote_(std::string_view v) {
        s_ += '"';
        for (char c : v) {
            if (c == '"' || c == '\\') {
                s_ += '\\';
                s_ += c;
            } else if (static_cast<unsigned char>(c) < 0x20) {
                char buf[8];
                std::snprintf(buf, sizeof buf, "\\u%04x", c);
                s_ += buf;
            } else {
                s_ += c;
            }
        }
        s_ += '"';
    }
    std::string s_;
};

}  // namespace sdfprune::cli
