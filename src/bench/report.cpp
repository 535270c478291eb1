// report.cpp — the benchmark's outputs: the machine description, the JSON object of
// `sdfprune bench -o`, and the markdown tables beside the paper's Tables 1–2 (Barbier et al.,
// EG 2025) with speed-ups over the naive baseline.
#include <sys/utsname.h>

#include <rapidjson/stringbuffer.h>
#include <rapidjson/writer.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "sdfprune/bench.hpp"

namespace sdfprune {

// ---- machine ---------------------------------------------------------------------------------

namespace {

// The value of the first line of `path` starting with `key` (after the ':' or '='), trimmed of
// spaces and quotes; "" when absent.
std::string field_of(const std::string& path, const std::string& key, char sep) {
    std::ifstream in(path);
    std::string line;
    while (std::getline(in, line)) {
        if (!line.starts_with(key)) continue;
        const size_t at = line.find(sep);
        if (at == std::string::npos) continue;
        std::string v = line.substr(at + 1);
        const auto junk = [](char c) { return c == ' ' || c == '\t' || c == '"'; };
        while (!v.empty() && junk(v.front())) v.erase(v.begin());
        while (!v.empty() && junk(v.back())) v.pop_back();
        return v;
    }
    return "";
}

}  // namespace

MachineInfo machine_info(int threads) {
    MachineInfo m;
    m.cpu = field_of("/proc/cpuinfo", "model name", ':');
    if (m.cpu.empty()) m.cpu = "unknown";
    m.cores = std::thread::hardware_concurrency();
    m.threads = threads;
    const std::string mem = field_of("/proc/meminfo", "MemTotal", ':');  // "16318864 kB"
    m.memory_bytes = mem.empty() ? 0 : std::stoull(mem) * 1024;
    m.os = field_of("/etc/os-release", "PRETTY_NAME", '=');
    utsname u{};
    if (::uname(&u) == 0)
        m.os +=
            (m.os.empty() ? "" : ", ") + std::string(u.sysname) + " " + u.release + " " + u.machine;
#if defined(__clang__)
    m.compiler = __VERSION__;
#elif defined(__GNUC__)
    m.compiler = std::string("GCC ") + __VERSION__;
#else
    m.compiler = "unknown";
#endif
    const std::time_t now = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&now, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    m.date = buf;
    return m;
}

// ---- JSON ------------------------------------------------------------------------------------

std::string bench_json(const MachineInfo& m, std::span<const BenchRow> rows) {
    rapidjson::StringBuffer buf;
    rapidjson::Writer<rapidjson::StringBuffer> w(buf);
    const auto key = [&](const char* k) { w.Key(k); };
    const auto num = [&](const char* k, double v) {
        key(k);
        if (std::isfinite(v))
            w.Double(v);
        else
            w.Null();
    };
    const auto u64 = [&](const char* k, uint64_t v) {
        key(k);
        w.Uint64(v);
    };
    const auto str = [&](const char* k, const std::string& v) {
        key(k);
        w.String(v.c_str(), rapidjson::SizeType(v.size()));
    };
    w.StartObject();
    key("machine");
    w.StartObject();
    str("cpu", m.cpu);
    u64("cores", m.cores);
    key("threads");
    w.Int(m.threads);
    u64("memory_bytes", m.memory_bytes);
    str("os", m.os);
    str("compiler", m.compiler);
    str("date", m.date);
    w.EndObject();
    key("rows");
    w.StartArray();
    for (const BenchRow& r : rows) {
        w.StartObject();
        str("scene", r.scene);
        str("source", r.source);
        u64("nodes", r.nodes);
        u64("primitives", r.primitives);
        str("variant", variant_name(r.variant));
        u64("width", r.width);
        u64("height", r.height);
        u64("res", r.res);
        u64("grid", r.grid);
        num("prune_ms", r.prune_ms);
        num("trace_ms", r.trace_ms);
        num("discretize_ms", r.discretize_ms);
        u64("prune_peak_bytes", r.prune_peak_bytes);
        u64("trace_bytes", r.trace_bytes);
        num("active_avg", r.active_avg);
        num("active_std", r.active_std);
        u64("active_max", r.active_max);
        num("near_field_fraction", r.near_field_fraction);
        key("estimate");
        w.Bool(r.estimate());
        key("estimated");
        w.StartArray();
        const auto flag = [&](bool on, const char* name) {
            if (on) w.String(name);
        };
        flag(r.prune_estimated, "prune_ms");
        flag(r.trace_estimated, "trace_ms");
        flag(r.discretize_estimated, "discretize_ms");
        if (r.stats_estimated)
            for (const char* f : {"prune_peak_bytes", "trace_bytes", "active_avg", "active_std",
                                  "active_max", "near_field_fraction"})
                w.String(f);
        w.EndArray();
        key("sample");
        w.StartObject();
        if (r.prune_estimated) num("prune_ms", r.prune_sample);
        if (r.trace_estimated) num("trace_ms", r.trace_sample);
        if (r.discretize_estimated) num("discretize_ms", r.discretize_sample);
        w.EndObject();
        w.EndObject();
    }
    w.EndArray();
    w.EndObject();
    return std::string(buf.GetString(), buf.GetSize());
}

// ---- plot ------------------------------------------------------------------------------------

std::vector<PlotSeries> bench_cost_series(std::span<const BenchRow> rows) {
    std::vector<const BenchRow*> sorted;
    for (const BenchRow& r : rows) sorted.push_back(&r);
    std::stable_sort(sorted.begin(), sorted.end(), [](const BenchRow* a, const BenchRow* b) {
        return a->primitives < b->primitives;
    });
    struct Spec {
        const char* label;
        Variant variant;
        double BenchRow::*ms;
        bool BenchRow::*estimated;
    };
    const Spec specs[] = {
        {"prune", Variant::kOurs, &BenchRow::prune_ms, &BenchRow::prune_estimated},
        {"trace", Variant::kOurs, &BenchRow::trace_ms, &BenchRow::trace_estimated},
        {"discretize", Variant::kOurs, &BenchRow::discretize_ms, &BenchRow::discretize_estimated},
        {"naive trace", Variant::kNaive, &BenchRow::trace_ms, &BenchRow::trace_estimated},
        {"naive discretize", Variant::kNaive, &BenchRow::discretize_ms,
         &BenchRow::discretize_estimated},
    };
    std::vector<PlotSeries> out;
    for (const Spec& spec : specs) {
        PlotSeries s;
        s.label = spec.label;
        for (const BenchRow* r : sorted) {
            if (r->variant != spec.variant || !std::isfinite(r->*spec.ms)) continue;
            s.x.push_back(double(r->primitives));
            s.y.push_back(r->*spec.ms);
            s.estimated.push_back(r->*spec.estimated);
        }
        if (!s.x.empty()) out.push_back(std::move(s));
    }
    return out;
}

// ---- markdown --------------------------------------------------------------------------------

namespace {

std::string fmt(const char* f, double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, f, v);
    return buf;
}

const char* approx(bool estimated) {
    return estimated ? "≈" : "";
}

std::string ms_text(double ms, bool estimated = false) {
    if (!std::isfinite(ms)) return "–";
    std::string s;
    if (ms < 1)
        s = fmt("%.3f ms", ms);
    else if (ms < 10)
        s = fmt("%.2f ms", ms);
    else if (ms < 1000)
        s = fmt("%.1f ms", ms);
    else if (ms < 1e5)
        s = fmt("%.2f s", ms / 1e3);
    else if (ms < 3.6e6)
        s = fmt("%.0f s", ms / 1e3);
    else
        s = fmt("%.1f h", ms / 3.6e6);
    return approx(estimated) + s;
}

std::string ratio_text(double r, bool estimated = false) {
    if (!std::isfinite(r) || r <= 0) return "–";
    return std::string(approx(estimated)) + (r < 10 ? fmt("×%.1f", r) : fmt("×%.0f", r));
}

std::string bytes_text(double b, bool estimated = false) {
    std::string s;
    if (b < 1e6)
        s = fmt("%.1f kB", b / 1e3);
    else if (b < 1e9)
        s = fmt("%.1f MB", b / 1e6);
    else
        s = fmt("%.2f GB", b / 1e9);
    return approx(estimated) + s;
}

std::string active_text(double avg, double stdev, bool estimated = false) {
    if (!std::isfinite(avg)) return "–";
    return approx(estimated) + fmt("%.3f", avg) + " ± " + fmt("%.3f", stdev);
}

// The paper's figure: "—" where its table is empty (overflowed its 5.7 GB buffer), "x" where
// the run did not finish.
std::string paper_ms(double ms, bool dnf) {
    if (dnf) return "x";
    return std::isfinite(ms) ? ms_text(ms) : "—";
}

double ratio(double num, double den) {
    return std::isfinite(num) && std::isfinite(den) && den > 0 ? num / den : NAN;
}

struct SceneRows {
    std::string name;
    std::vector<const BenchRow*> rows;
    const BenchRow* of(Variant v) const {
        for (const BenchRow* r : rows)
            if (r->variant == v) return r;
        return nullptr;
    }
};

std::vector<SceneRows> group(std::span<const BenchRow> rows) {
    std::vector<SceneRows> out;
    for (const BenchRow& r : rows) {
        auto it = std::find_if(out.begin(), out.end(),
                               [&](const SceneRows& s) { return s.name == r.scene; });
        if (it == out.end()) {
            out.push_back({r.scene, {}});
            it = out.end() - 1;
        }
        it->rows.push_back(&r);
    }
    return out;
}

// Speed-ups of a row over the scene's naive row (NaN when either is missing).
struct Speedups {
    double trace = NAN, prune_trace = NAN, discretize = NAN;
    bool estimated = false;
};
Speedups speedups(const BenchRow& r, const BenchRow* naive) {
    Speedups s;
    if (!naive) return s;
    s.trace = ratio(naive->trace_ms, r.trace_ms);
    s.prune_trace = ratio(naive->trace_ms, r.prune_ms + r.trace_ms);
    s.discretize = ratio(naive->discretize_ms, r.discretize_ms);
    s.estimated = naive->estimate() || r.estimate();
    return s;
}

void scene_section(std::ostringstream& md, const SceneRows& s) {
    const BenchRow& first = *s.rows.front();
    const BenchRow* naive = s.of(Variant::kNaive);
    md << "## " << s.name << " (" << first.nodes << " nodes, " << first.primitives
       << " primitives)\n\n";
    md << "`" << first.source << "`: image " << first.width << "×" << first.height
       << " (one primary + one shadow ray per pixel), discretization " << first.res << "³";
    const uint32_t grid = s.of(Variant::kOurs) ? s.of(Variant::kOurs)->grid : first.grid;
    if (grid) md << ", pruning grid " << grid << "³";
    md << ".\n\n";
    md << "| variant | prune | trace | discretize | trace speed-up | prune + trace speed-up | "
          "discretize speed-up | pruning peak memory | memory while tracing | near-field cells | "
          "active prims avg ± std | max |\n";
    md << "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const BenchRow* r : s.rows) {
        const Speedups sp = speedups(*r, naive);
        const bool is_naive = r->variant == Variant::kNaive;
        md << "| " << variant_name(r->variant) << " | "
           << (is_naive ? "–" : ms_text(r->prune_ms, r->prune_estimated)) << " | "
           << ms_text(r->trace_ms, r->trace_estimated) << " | "
           << ms_text(r->discretize_ms, r->discretize_estimated) << " | "
           << (is_naive ? "×1" : ratio_text(sp.trace, sp.estimated)) << " | "
           << (is_naive ? "×1" : ratio_text(sp.prune_trace, sp.estimated)) << " | "
           << (is_naive ? "×1" : ratio_text(sp.discretize, sp.estimated)) << " | "
           << (is_naive ? "–" : bytes_text(double(r->prune_peak_bytes), r->stats_estimated))
           << " | " << bytes_text(double(r->trace_bytes), r->stats_estimated) << " | "
           << approx(r->stats_estimated) << fmt("%.2f %%", 100 * r->near_field_fraction) << " | "
           << active_text(r->active_avg, r->active_std, r->stats_estimated) << " | "
           << (r->stats_estimated ? "≥" : "") << r->active_max << " |\n";
    }
    md << "\n";

    const PaperScene* p = find_paper_scene(s.name);
    if (!p) return;
    md << "Paper, " << p->name << " (" << p->nodes
       << " nodes; Barbier et al. 2025, Tables 1–2; laptop RTX 4060, 1920×1080, 256³):\n\n";
    md << "| variant | prune | trace | discretize | trace speed-up | prune + trace speed-up | "
          "discretize speed-up | pruning memory | memory while tracing | active prims avg ± std "
          "| max |\n";
    md << "|---|---|---|---|---|---|---|---|---|---|---|\n";
    const PaperFigures& base = (*p)[Variant::kNaive];
    for (Variant v : kAllVariants) {
        const PaperFigures& f = (*p)[v];
        const bool is_naive = v == Variant::kNaive;
        const auto gb = [](double g, bool lower) {
            return std::isfinite(g) ? (lower ? "≥ " : "") + fmt("%.2f GB", g) : std::string("—");
        };
        md << "| " << variant_name(v) << " | " << (is_naive ? "–" : paper_ms(f.prune_ms, false))
           << " | " << paper_ms(f.trace_ms, f.did_not_finish) << " | "
           << paper_ms(f.discretize_ms, f.did_not_finish) << " | "
           << (is_naive ? "×1" : ratio_text(ratio(base.trace_ms, f.trace_ms))) << " | "
           << (is_naive ? "×1" : ratio_text(ratio(base.trace_ms, f.prune_ms + f.trace_ms))) << " | "
           << (is_naive ? "×1" : ratio_text(ratio(base.discretize_ms, f.discretize_ms))) << " | "
           << (is_naive ? "–" : gb(f.prune_gb, f.prune_gb_lower_bound)) << " | "
           << gb(f.trace_gb, false) << " | "
           << (is_naive ? "all " + std::to_string(p->nodes) + " nodes"
                        : active_text(f.active_avg, f.active_std))
           << " | " << (std::isfinite(f.active_max) ? fmt("%.0f", f.active_max) : "–") << " |\n";
    }
    md << "\n";
}

}  // namespace

std::string bench_markdown(const MachineInfo& m, std::span<const BenchRow> rows) {
    std::ostringstream md;
    md << "Measured by `sdfprune bench` on " << m.date << ": " << m.cpu << ", " << m.cores
       << " hardware threads (" << (m.threads > 0 ? std::to_string(m.threads) : "all") << " used), "
       << fmt("%.0f GiB", double(m.memory_bytes) / (1u << 30)) << " RAM, " << m.os << ", "
       << m.compiler << ".\n\n";
    md << "Speed-ups are over the naive baseline (the full tree at every query, same evaluator, "
          "same threads) measured in the same run. `≈`: estimated from a sample (the time of a "
          "sample of the pixels or cells, scaled to the full count; see `estimated` in the "
          "JSON), `≥`: the sample's maximum. `–`: not measured. The paper's figures (Barbier "
          "et al., \"Lipschitz Pruning: Hierarchical Simplification of Primitive-Based SDFs\", "
          "Eurographics 2025, Tables 1–2, laptop RTX 4060) are copied from bench/paper/*.csv; "
          "there `—` means its 5.7 GB buffer overflowed, `x` did not finish, `≥` a theoretical "
          "lower bound. Compare ratios and counts, not absolute times across machines.\n\n";

    const std::vector<SceneRows> scenes = group(rows);
    md << "## Summary\n\n";
    md << "| scene | nodes | trace speed-up | paper | discretize speed-up | paper | active prims "
          "avg (ours) | paper |\n";
    md << "|---|---|---|---|---|---|---|---|\n";
    for (const SceneRows& s : scenes) {
        const BenchRow* ours = s.of(Variant::kOurs);
        const BenchRow* naive = s.of(Variant::kNaive);
        const PaperScene* p = find_paper_scene(s.name);
        const Speedups sp = ours ? speedups(*ours, naive) : Speedups{};
        std::string pt = "–", pd = "–", pa = "–";
        if (p) {
            const PaperFigures &po = (*p)[Variant::kOurs], &pb = (*p)[Variant::kNaive];
            pt = ratio_text(ratio(pb.trace_ms, po.trace_ms));
            pd = ratio_text(ratio(pb.discretize_ms, po.discretize_ms));
            pa = std::isfinite(po.active_avg) ? fmt("%.2f", po.active_avg) : "–";
        }
        md << "| " << s.name << " | " << s.rows.front()->nodes << " | "
           << ratio_text(sp.trace, sp.estimated) << " | " << pt << " | "
           << ratio_text(sp.discretize, sp.estimated) << " | " << pd << " | "
           << (ours ? fmt("%.3f", ours->active_avg) : "–") << " | " << pa << " |\n";
    }
    md << "\n";
    for (const SceneRows& s : scenes) scene_section(md, s);
    return md.str();
}

}  // namespace sdfprune
