// bench_test.cpp — `sdfprune bench`: rows for every variant, JSON and markdown outputs, estimates
// under a tiny budget, the embedded paper tables, and the log-log plot writer.
#include <gtest/gtest.h>
#include <rapidjson/document.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "sdfprune/bench.hpp"
#include "sdfprune/builtin.hpp"
#include "sdfprune/plot.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

std::string last_line(const std::string& s) {
    std::string t = s;
    while (!t.empty() && t.back() == '\n') t.pop_back();
    const size_t nl = t.rfind('\n');
    return nl == std::string::npos ? t : t.substr(nl + 1);
}

std::string temp_path(const std::string& name) {
    return ::testing::TempDir() + "sdfprune_bench_" + std::to_string(::getpid()) + "_" + name;
}

// clang-format off
const char* const kRowFields[] = {
    "scene", "source", "nodes", "primitives", "variant", "width", "height", "res", "grid",
    "prune_ms", "trace_ms", "discretize_ms", "prune_peak_bytes", "trace_bytes", "active_avg",
    "active_std", "active_max", "near_field_fraction", "estimate", "estimated", "sample"};
// clang-format on

// Checks the shape of the bench JSON object; returns the rows.
const rapidjson::Value& check_bench_json(const rapidjson::Document& d) {
    EXPECT_TRUE(d.IsObject());
    EXPECT_TRUE(d.HasMember("machine") && d["machine"].IsObject());
    for (const char* f : {"cpu", "cores", "threads", "memory_bytes", "os", "compiler", "date"})
        EXPECT_TRUE(d["machine"].HasMember(f)) << f;
    EXPECT_TRUE(d.HasMember("rows") && d["rows"].IsArray());
    for (const auto& r : d["rows"].GetArray())
        for (const char* f : kRowFields) EXPECT_TRUE(r.HasMember(f)) << f;
    return d["rows"];
}

const rapidjson::Value* find_row(const rapidjson::Value& rows, const std::string& scene,
                                 const std::string& variant) {
    for (const auto& r : rows.GetArray())
        if (scene == r["scene"].GetString() && variant == r["variant"].GetString()) return &r;
    return nullptr;
}

TEST(BenchCli, RowsForEveryVariantJsonAndMarkdown) {
    const std::string json_path = temp_path("out.json"), md_path = temp_path("out.md"),
                      png_path = temp_path("cost.png");
    const test::CliResult r = test::run_cli(
        "bench builtin:sphere builtin:demo --width 64 --height 36 --grid 32 --res 32 -o " +
        json_path + " --md " + md_path + " --plot " + png_path + " --json --quiet");
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string line = last_line(r.out);
    EXPECT_EQ(line + "\n", slurp(json_path)) << "-o and --json give the same object";

    rapidjson::Document d;
    d.Parse(slurp(json_path).c_str());
    ASSERT_FALSE(d.HasParseError()) << "the -o file is JSON";
    const rapidjson::Value& rows = check_bench_json(d);
    ASSERT_EQ(rows.Size(), 8u);
    for (const char* scene : {"sphere", "demo"}) {
        for (Variant v : kAllVariants) {
            const rapidjson::Value* row = find_row(rows, scene, variant_name(v));
            ASSERT_NE(row, nullptr) << scene << " " << variant_name(v);
            EXPECT_FALSE((*row)["estimate"].GetBool()) << "20 s budget: everything measured";
            EXPECT_GT((*row)["trace_ms"].GetDouble(), 0);
            EXPECT_GT((*row)["discretize_ms"].GetDouble(), 0);
            EXPECT_GE((*row)["active_avg"].GetDouble(), 1.0);
            EXPECT_GT((*row)["trace_bytes"].GetUint64(), 0u);
            EXPECT_EQ((*row)["res"].GetUint(), 32u);
            if (v == Variant::kNaive) {
                EXPECT_EQ((*row)["prune_ms"].GetDouble(), 0);
                EXPECT_EQ((*row)["grid"].GetUint(), 0u);
            } else {
                EXPECT_GT((*row)["prune_ms"].GetDouble(), 0);
                EXPECT_EQ((*row)["grid"].GetUint(), 32u);
            }
        }
        // Speed-ups over naive are positive ratios.
        const rapidjson::Value* ours = find_row(rows, scene, "ours");
        const rapidjson::Value* naive = find_row(rows, scene, "naive");
        EXPECT_GT((*naive)["trace_ms"].GetDouble() / (*ours)["trace_ms"].GetDouble(), 0);
        EXPECT_GT((*naive)["discretize_ms"].GetDouble() / (*ours)["discretize_ms"].GetDouble(), 0);
    }
    // Pruning finds demo's cells need far fewer primitives than all of them.
    EXPECT_LT((*find_row(rows, "demo", "ours"))["active_avg"].GetDouble(),
              (*find_row(rows, "demo", "naive"))["active_avg"].GetDouble() / 5);

    const std::string md = slurp(md_path);
    for (const char* s : {"## Summary", "## sphere (1 nodes", "## demo (", "| variant | prune |",
                          "| ours |", "| no_farfield |", "| no_hierarchy |", "| naive |",
                          "trace speed-up", "discretize speed-up"})
        EXPECT_NE(md.find(s), std::string::npos) << s;
    EXPECT_EQ(md.find("Paper, "), std::string::npos) << "the paper has neither scene";
    std::istringstream lines(md);
    for (std::string l; std::getline(lines, l);)
        if (l.starts_with("|")) {
            EXPECT_EQ(l.find("≈"), std::string::npos) << "nothing estimated: " << l;
        }
    EXPECT_EQ(slurp(png_path).substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    fs::remove(json_path);
    fs::remove(md_path);
    fs::remove(png_path);
}

TEST(BenchCli, TinyBudgetMarksEstimates) {
    const test::CliResult r = test::run_cli(
        "bench builtin:demo --variants no_hierarchy,naive --width 64 --height 36 --grid 32 "
        "--res 64 --budget-s 0.000001 --json --quiet");
    ASSERT_EQ(r.status, 0) << r.err;
    rapidjson::Document d;
    d.Parse(last_line(r.out).c_str());
    ASSERT_FALSE(d.HasParseError());
    const rapidjson::Value& rows = check_bench_json(d);
    ASSERT_EQ(rows.Size(), 2u);

    const rapidjson::Value& naive = *find_row(rows, "demo", "naive");
    EXPECT_TRUE(naive["estimate"].GetBool());
    std::set<std::string> est;
    for (const auto& f : naive["estimated"].GetArray()) est.insert(f.GetString());
    EXPECT_TRUE(est.count("trace_ms") && est.count("discretize_ms"));
    for (const char* f : {"trace_ms", "discretize_ms"}) {
        EXPECT_GT(naive[f].GetDouble(), 0) << f;
        const double sample = naive["sample"][f].GetDouble();
        EXPECT_GT(sample, 0) << f;
        EXPECT_LT(sample, 1) << f;
    }

    const rapidjson::Value& nh = *find_row(rows, "demo", "no_hierarchy");
    EXPECT_TRUE(nh["estimate"].GetBool());
    EXPECT_GT(nh["prune_ms"].GetDouble(), 0);
    EXPECT_TRUE(nh["trace_ms"].IsNull()) << "the grid was not built";
    EXPECT_TRUE(nh["discretize_ms"].IsNull());
    EXPECT_GE(nh["active_avg"].GetDouble(), 1.0);
    EXPECT_GT(nh["near_field_fraction"].GetDouble(), 0);
}

TEST(BenchCli, BadArgumentsExitTwo) {
    EXPECT_EQ(test::run_cli("bench builtin:sphere --variants ours,bogus --quiet").status, 2);
    EXPECT_EQ(test::run_cli("bench builtin:sphere -o " + temp_path("x.txt") + " --quiet").status,
              2);
    EXPECT_EQ(test::run_cli("bench builtin:nosuch --quiet").status, 2);
}

// A variant on the demo scene measured (a large budget), then estimated from a sample (a tiny
// one), with options `o`.
struct MeasuredAndEstimated {
    BenchRow measured, estimated;
};
MeasuredAndEstimated measure_and_estimate(Variant v, BenchOptions o) {
    const Scene sc = builtin_scene("demo");
    MeasuredAndEstimated r;
    r.measured = run_variant(sc, v, o);
    o.budget_s = 1e-6;
    r.estimated = run_variant(sc, v, o);
    EXPECT_FALSE(r.measured.estimate());
    return r;
}
// An estimated time lands within 5x of the measured one.
void expect_near_time(double estimated, double measured, const char* what) {
    EXPECT_GT(estimated, measured / 5) << what;
    EXPECT_LT(estimated, measured * 5) << what;
}

TEST(Bench, EstimateIsCloseToMeasurement) {
    // The naive trace and discretization: the estimate scales a uniform sample of the image
    // (of the cells), so it lands near the real time.
    BenchOptions o;
    o.width = 160;
    o.height = 90;
    o.res = 48;
    const MeasuredAndEstimated r = measure_and_estimate(Variant::kNaive, o);
    ASSERT_TRUE(r.estimated.trace_estimated && r.estimated.discretize_estimated);
    expect_near_time(r.estimated.trace_ms, r.measured.trace_ms, "trace");
    expect_near_time(r.estimated.discretize_ms, r.measured.discretize_ms, "discretize");
}

TEST(Bench, NoHierarchyEstimateIsCloseToMeasurement) {
    // The no_hierarchy pruning, estimated from a sample of groups of 64 neighbouring cells
    // pruned as prune() prunes them: the sample's near-field share and active primitives land
    // near the grid's, and its time near the real one.
    BenchOptions o;
    o.width = 32;
    o.height = 18;
    o.res = 16;
    o.grid = 48;
    const MeasuredAndEstimated r = measure_and_estimate(Variant::kNoHierarchy, o);
    const BenchRow &measured = r.measured, &estimated = r.estimated;
    ASSERT_TRUE(estimated.prune_estimated && estimated.stats_estimated);
    expect_near_time(estimated.prune_ms, measured.prune_ms, "prune");
    EXPECT_NEAR(estimated.near_field_fraction, measured.near_field_fraction,
                0.25 * measured.near_field_fraction);
    EXPECT_NEAR(estimated.active_avg, measured.active_avg, 0.05 * measured.active_avg);
    EXPECT_LE(estimated.active_max, measured.active_max);  // the sample's: a lower bound
}

TEST(Bench, VariantsOnSphere) {
    const Scene sc = builtin_scene("sphere");
    BenchOptions o;
    o.width = 32;
    o.height = 18;
    o.res = 16;
    for (Variant v : kAllVariants) {
        const BenchRow r = run_variant(sc, v, o);
        EXPECT_EQ(r.variant, v);
        EXPECT_EQ(r.nodes, 1u);
        EXPECT_DOUBLE_EQ(r.active_avg, 1.0) << variant_name(v);
        EXPECT_EQ(r.active_max, 1u);
        EXPECT_FALSE(r.estimate());
        if (v == Variant::kNoFarField || v == Variant::kNaive)
            EXPECT_DOUBLE_EQ(r.near_field_fraction, 1.0);
        else
            EXPECT_LT(r.near_field_fraction, 1.0);
    }
    Variant v;
    EXPECT_TRUE(variant_from_name("no_hierarchy", v));
    EXPECT_EQ(v, Variant::kNoHierarchy);
    EXPECT_FALSE(variant_from_name("fast", v));
    EXPECT_EQ(scene_display_name("builtin:demo"), "demo");
    EXPECT_EQ(scene_display_name("../shared/scenes/car-chase.json"), "car-chase");
    EXPECT_GT(scene_bytes(sc), 0u);
}

TEST(Bench, CostSeriesForThePlot) {
    std::vector<BenchRow> rows;
    for (uint32_t prims : {1000u, 10u}) {
        for (Variant v : {Variant::kOurs, Variant::kNaive}) {
            BenchRow r;
            r.primitives = prims;
            r.variant = v;
            r.prune_ms = v == Variant::kOurs ? prims * 0.01 : 0;
            r.trace_ms = prims * (v == Variant::kOurs ? 0.1 : 10.0);
            r.discretize_ms = prims * 0.2;
            r.trace_estimated = v == Variant::kNaive && prims > 100;
            rows.push_back(r);
        }
    }
    const std::vector<PlotSeries> s = bench_cost_series(rows);
    ASSERT_EQ(s.size(), 5u);
    EXPECT_EQ(s[0].label, "prune");
    EXPECT_EQ(s[3].label, "naive trace");
    EXPECT_EQ(s[3].x, (std::vector<double>{10, 1000}));
    EXPECT_EQ(s[3].y, (std::vector<double>{100, 10000}));
    EXPECT_EQ(s[3].estimated, (std::vector<bool>{false, true}));
}

TEST(BenchPaper, EmbeddedTablesMatchTheCsvFiles) {
    const fs::path dir = fs::path(__FILE__).parent_path().parent_path() / "bench" / "paper";
    if (!fs::exists(dir / "table1.csv")) GTEST_SKIP() << "source tree not found at " << dir;
    EXPECT_EQ(paper_table1_csv(), slurp(dir / "table1.csv")) << "run python3 bench/paper/embed.py";
    EXPECT_EQ(paper_table2_csv(), slurp(dir / "table2.csv")) << "run python3 bench/paper/embed.py";
    EXPECT_NE(paper_table1_csv().find("Barbier"), std::string::npos) << "citation line";
}

TEST(BenchPaper, ParsedFigures) {
    ASSERT_EQ(paper_scenes().size(), 14u);
    const PaperScene* m = find_paper_scene("molecule");
    ASSERT_NE(m, nullptr);
    EXPECT_EQ(m->nodes, 1999u);
    EXPECT_DOUBLE_EQ((*m)[Variant::kOurs].trace_ms, 6.97);
    EXPECT_DOUBLE_EQ((*m)[Variant::kNaive].discretize_ms, 841.65);
    EXPECT_DOUBLE_EQ((*m)[Variant::kOurs].active_avg, 1.12);
    EXPECT_DOUBLE_EQ((*m)[Variant::kOurs].active_max, 62);
    EXPECT_TRUE(std::isnan((*m)[Variant::kNoFarField].prune_ms)) << "overflowed in the paper";
    EXPECT_DOUBLE_EQ((*m)[Variant::kNoHierarchy].prune_gb, 188);
    EXPECT_TRUE((*m)[Variant::kNoHierarchy].prune_gb_lower_bound);
    const PaperScene* cc = find_paper_scene("car-chase");
    ASSERT_NE(cc, nullptr);
    EXPECT_EQ(cc->name, "Car Chase");
    EXPECT_NE(find_paper_scene("Train_Station"), nullptr);
    EXPECT_TRUE(find_paper_scene("fluid")->figures[int(Variant::kNaive)].did_not_finish);
    EXPECT_EQ(find_paper_scene("demo"), nullptr);
}

TEST(BenchPaper, MarkdownShowsThePaperBesideOurs) {
    std::vector<BenchRow> rows;
    for (Variant v : kAllVariants) {
        BenchRow r;
        r.scene = "molecule";
        r.source = "molecule.json";
        r.nodes = 2001;
        r.primitives = 1001;
        r.variant = v;
        r.width = 1920;
        r.height = 1080;
        r.res = r.grid = 256;
        r.prune_ms = v == Variant::kNaive ? 0 : 10;
        r.trace_ms = v == Variant::kNaive ? 1000 : 10;
        r.discretize_ms = v == Variant::kNaive ? 2000 : 4;
        r.trace_estimated = r.discretize_estimated = v == Variant::kNaive;
        r.active_avg = 1.1;
        rows.push_back(r);
    }
    const std::string md = bench_markdown(machine_info(), rows);
    EXPECT_NE(md.find("Paper, Molecule (1999 nodes"), std::string::npos);
    EXPECT_NE(md.find("≈×100"), std::string::npos) << "trace speed-up over an estimated naive";
    EXPECT_NE(md.find("≈×500"), std::string::npos) << "discretize speed-up";
    EXPECT_NE(md.find("×86"), std::string::npos) << "the paper's trace speed-up";
    EXPECT_NE(md.find("≥ 188.00 GB"), std::string::npos) << "the paper's lower bound";
}

TEST(Plot, WritesALogLogPng) {
    std::vector<PlotSeries> series(3);
    const char* names[] = {"prune", "trace", "naive"};
    for (int k = 0; k < 3; ++k) {
        series[k].label = names[k];
        for (double n = 100; n <= 1e6; n *= 10) {
            series[k].x.push_back(n);
            series[k].y.push_back(std::pow(n, 0.5 + 0.25 * k) * 0.01);
            series[k].estimated.push_back(k == 2 && n > 1e4);
        }
    }
    series[0].y[2] = 0;  // skipped on a log axis
    PlotOptions po;
    po.title = "cost vs primitives";
    po.x_min = 100;
    po.x_max = 1e6;
    const Image img = draw_loglog_plot(series, po);
    ASSERT_EQ(img.width, po.width);
    ASSERT_EQ(img.height, po.height);
    size_t ink = 0, colored = 0;
    for (size_t i = 0; i < img.rgb.size(); i += 3) {
        const int r = img.rgb[i], g = img.rgb[i + 1], b = img.rgb[i + 2];
        ink += r < 100 && g < 100 && b < 100;
        colored += std::max({r, g, b}) - std::min({r, g, b}) > 80;
    }
    EXPECT_GT(ink, 500u) << "frame, ticks and labels";
    EXPECT_GT(colored, 500u) << "the series' lines";

    const std::string path = temp_path("plot.png");
    write_loglog_plot(path, series, po);
    const std::string png = slurp(path);
    ASSERT_GT(png.size(), 33u);
    EXPECT_EQ(png.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    EXPECT_EQ(png.substr(12, 4), "IHDR");
    const auto be32 = [&](size_t at) {
        return uint32_t(uint8_t(png[at])) << 24 | uint32_t(uint8_t(png[at + 1])) << 16 |
               uint32_t(uint8_t(png[at + 2])) << 8 | uint32_t(uint8_t(png[at + 3]));
    };
    EXPECT_EQ(be32(16), po.width);
    EXPECT_EQ(be32(20), po.height);
    fs::remove(path);

    EXPECT_EQ(decade_label(0), "1");
    EXPECT_EQ(decade_label(3), "1k");
    EXPECT_EQ(decade_label(6), "1M");
    EXPECT_EQ(decade_label(-2), "0.01");
    PlotSeries bad;
    bad.x = {1, 2};
    bad.y = {1};
    EXPECT_THROW(draw_loglog_plot(std::span(&bad, 1)), std::invalid_argument);
    // Nothing plottable still draws the axes.
    EXPECT_EQ(draw_loglog_plot({}).width, PlotOptions{}.width);
}

}  // namespace
}  // namespace sdfprune
