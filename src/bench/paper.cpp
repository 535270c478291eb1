// paper.cpp — the paper's Tables 1 and 2 (Barbier et al., EG 2025) parsed from the embedded CSVs
// (paper_tables.cpp, generated from bench/paper/*.csv), and scene-name matching.
#include <cctype>
#include <charconv>
#include <cmath>
#include <map>
#include <stdexcept>

#include "sdfprune/bench.hpp"

namespace sdfprune {
namespace {

std::vector<std::string> split(std::string_view line) {
    std::vector<std::string> out;
    size_t start = 0;
    for (;;) {
        const size_t comma = line.find(',', start);
        out.emplace_back(
            line.substr(start, comma == std::string_view::npos ? line.npos : comma - start));
        if (comma == std::string_view::npos) return out;
        start = comma + 1;
    }
}

// Header name -> column index, and the data rows, of a CSV with '#' comment lines.
struct Csv {
    std::map<std::string, size_t> column;
    std::vector<std::vector<std::string>> rows;
};

Csv parse_csv(std::string_view text) {
    Csv csv;
    bool header = true;
    while (!text.empty()) {
        const size_t nl = text.find('\n');
        std::string_view line = text.substr(0, nl);
        text.remove_prefix(nl == text.npos ? text.size() : nl + 1);
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        if (line.empty() || line.front() == '#') continue;
        std::vector<std::string> fields = split(line);
        if (header) {
            for (size_t i = 0; i < fields.size(); ++i) csv.column[fields[i]] = i;
            header = false;
        } else {
            csv.rows.push_back(std::move(fields));
        }
    }
    return csv;
}

// A cell of the tables: "" -> NaN; "x" -> NaN and did-not-finish; "11.5*" -> 11.5, starred.
double cell(const Csv& csv, const std::vector<std::string>& row, const std::string& name,
            bool* starred = nullptr, bool* dnf = nullptr) {
    const auto it = csv.column.find(name);
    if (it == csv.column.end()) throw std::logic_error("paper table: no column " + name);
    std::string s = it->second < row.size() ? row[it->second] : "";
    if (s == "x") {
        if (dnf) *dnf = true;
        return NAN;
    }
    if (!s.empty() && s.back() == '*') {
        if (starred) *starred = true;
        s.pop_back();
    }
    if (s.empty()) return NAN;
    double v = NAN;
    const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || p != s.data() + s.size())
        throw std::logic_error("paper table: bad number \"" + s + "\"");
    return v;
}

std::string normalized(std::string_view name) {
    std::string out;
    for (char c : name)
        if (c != ' ' && c != '-' && c != '_')
            out += char(std::tolower(static_cast<unsigned char>(c)));
    return out;
}

std::vector<PaperScene> parse_paper() {
    const Csv t1 = parse_csv(paper_table1_csv()), t2 = parse_csv(paper_table2_csv());
    std::vector<PaperScene> scenes;
    static const char* const kPrefix[4] = {"ours", "noff", "nohier", "base"};
    for (const auto& row : t1.rows) {
        PaperScene s;
        s.name = row.at(t1.column.at("scene"));
        s.nodes = uint32_t(cell(t1, row, "nodes"));
        for (int v = 0; v < 4; ++v) {
            PaperFigures& f = s.figures[v];
            const std::string p = kPrefix[v];
            if (v < 3) {
                f.prune_ms = cell(t1, row, p + "_Tp");
                f.prune_gb = cell(t1, row, p + "_Mp", &f.prune_gb_lower_bound);
            }
            f.trace_ms = cell(t1, row, p + "_Ts", nullptr, &f.did_not_finish);
            f.discretize_ms = cell(t1, row, p + "_Td", nullptr, &f.did_not_finish);
            f.trace_gb = cell(t1, row, p + "_Ms");
        }
        scenes.push_back(std::move(s));
    }
    for (const auto& row : t2.rows) {
        const std::string name = row.at(t2.column.at("scene"));
        for (PaperScene& s : scenes) {
            if (s.name != name) continue;
            for (int v = 0; v < 2; ++v) {
                const std::string p = kPrefix[v];
                s.figures[v].active_avg = cell(t2, row, p + "_avg");
                s.figures[v].active_std = cell(t2, row, p + "_std");
                s.figures[v].active_max = cell(t2, row, p + "_max");
            }
        }
    }
    return scenes;
}

}  // namespace

const std::vector<PaperScene>& paper_scenes() {
    static const std::vector<PaperScene> scenes = parse_paper();
    return scenes;
}

const PaperScene* find_paper_scene(std::string_view name) {
    const std::string key = normalized(name);
    for (const PaperScene& s : paper_scenes())
        if (normalized(s.name) == key) return &s;
    return nullptr;
}

}  // namespace sdfprune
