// malformed_input_test.cpp — bad scene files and arguments via the CLI: status 2, one-line errors.
#include <gtest/gtest.h>
#include <rapidjson/document.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "sdfprune/eval.hpp"
#include "sdfprune/io.hpp"
#include "test_util.hpp"

namespace sdfprune {
namespace {

using test::run_cli;

// A valid scene of five nodes; each fragment is one node, so a case can break exactly one of them.
//   /                       union (k 0.1)
//   /leftChild              sub (k 0.05)
//   /leftChild/leftChild    sphere
//   /leftChild/rightChild   cylinder
//   /rightChild             box
enum Part { kRoot, kInner, kSphere, kCylinder, kBox, kPartCount };

const char* const kBase[kPartCount] = {
    R"({"aabb_min":[-2,-2,-2],"aabb_max":[2,2,2],"nodeType":"binaryOperator","blendMode":"union","blendRadius":0.1,"matrix":[1,0,0,0,0,1,0,0,0,0,1,0],"leftChild":@INNER@,"rightChild":@BOX@})",
    R"({"nodeType":"binaryOperator","blendMode":"sub","blendRadius":0.05,"matrix":[1,0,0,0.4,0,1,0,0,0,0,1,0],"leftChild":@SPHERE@,"rightChild":@CYLINDER@})",
    R"({"nodeType":"primitive","matrix":[1,0,0,0.1,0,1,0,0,0,0,1,0],"primitiveType":"sphere","radius":1.5,"color":[1,0,0]})",
    R"({"nodeType":"primitive","matrix":[1,0,0,0,0,1,0,0.3,0,0,1,0],"primitiveType":"cylinder","height":3,"radius":0.25,"round_x":0,"round_y":0})",
    R"({"nodeType":"primitive","matrix":[1,0,0,0,0,1,0,0.2,0,0,1,0],"primitiveType":"box","sides":[1,2,3],"bevel":[0.1,0.1,0.1,0.1],"round_x":0.05,"round_y":0})",
};

struct Edit {
    Part part = kRoot;
    std::string from, to;  // `from` must occur exactly once in the part
};

void replace_once(std::string& s, const std::string& from, const std::string& to) {
    const size_t at = s.find(from);
    ASSERT_NE(at, std::string::npos) << "'" << from << "' not in " << s;
    ASSERT_EQ(s.find(from, at + 1), std::string::npos) << "'" << from << "' twice in " << s;
    s.replace(at, from.size(), to);
}

std::string make_scene(const std::vector<Edit>& edits = {}) {
    std::string parts[kPartCount];
    for (int i = 0; i < kPartCount; ++i) parts[i] = kBase[i];
    for (const Edit& e : edits) replace_once(parts[e.part], e.from, e.to);
    std::string inner = parts[kInner];
    replace_once(inner, "@SPHERE@", parts[kSphere]);
    replace_once(inner, "@CYLINDER@", parts[kCylinder]);
    std::string root = parts[kRoot];
    replace_once(root, "@INNER@", inner);
    replace_once(root, "@BOX@", parts[kBox]);
    return root;
}

std::string temp_path(const std::string& name) {
    return ::testing::TempDir() + "sdfprune_malformed_" + std::to_string(::getpid()) + "_" + name;
}

std::string write_temp(const std::string& name, const std::string& text) {
    const std::string path = temp_path(name);
    std::ofstream(path, std::ios::binary) << text;
    return path;
}

std::string shell_quote(const std::string& s) {
    return "'" + s + "'";
}

// The CLI's contract for bad input: status 2, exactly one line on stderr naming the file.
void expect_one_line_error(const test::CliResult& r, const std::string& path) {
    EXPECT_EQ(r.status, 2) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_TRUE(!r.err.empty() && r.err.back() == '\n') << r.err;
    EXPECT_NE(r.err.find(path), std::string::npos) << r.err;
}

TEST(MalformedInput, BaseSceneIsValid) {
    const std::string path = write_temp("base.json", make_scene());
    const test::CliResult r = run_cli("info " + shell_quote(path));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(r.err, "");
    const Scene sc = load_scene(path);
    EXPECT_EQ(sc.size(), 5u);
    std::remove(path.c_str());
}

struct Case {
    const char* name;
    std::string text;
    std::string pointer;  // "" for file-level errors; else expected in the message, then ':'
};

std::vector<Case> malformed_cases() {
    const std::string base = make_scene();
    std::vector<Case> c = {
        {"not_json", "this is not json", ""},
        {"empty_file", "", ""},
        {"whitespace_only", " \n\t ", ""},
        {"truncated", base.substr(0, base.size() / 2), ""},
        {"trailing_garbage", base + " {}", ""},
        {"top_level_array", "[1, 2, 3]", ""},
        {"top_level_number", "42", ""},
        {"top_level_string", "\"scene\"", ""},
        // Wrong types.
        {"radius_is_string", make_scene({{kSphere, "\"radius\":1.5", "\"radius\":\"1.5\""}}),
         "/leftChild/leftChild/radius"},
        {"matrix_is_object",
         make_scene({{kBox, "\"matrix\":[1,0,0,0,0,1,0,0.2,0,0,1,0]", "\"matrix\":{\"m\":1}"}}),
         "/rightChild/matrix"},
        {"blend_radius_true",
         make_scene({{kInner, "\"blendRadius\":0.05", "\"blendRadius\":true"}}),
         "/leftChild/blendRadius"},
        {"blend_radius_null", make_scene({{kRoot, "\"blendRadius\":0.1", "\"blendRadius\":null"}}),
         "/blendRadius"},
        {"node_type_is_number",
         make_scene({{kCylinder, "\"nodeType\":\"primitive\"", "\"nodeType\":1"}}),
         "/leftChild/rightChild/nodeType"},
        {"child_is_array", make_scene({{kRoot, "\"rightChild\":@BOX@", "\"rightChild\":[@BOX@]"}}),
         "/rightChild"},
        {"matrix_entry_is_string", make_scene({{kSphere, "[1,0,0,0.1,", "[1,0,\"0\",0.1,"}}),
         "/leftChild/leftChild/matrix"},
        {"sides_entry_is_array", make_scene({{kBox, "\"sides\":[1,2,3]", "\"sides\":[1,[2],3]"}}),
         "/rightChild/sides"},
        // Missing required fields.
        {"missing_node_type", make_scene({{kBox, "\"nodeType\":\"primitive\",", ""}}),
         "/rightChild"},
        {"missing_matrix", make_scene({{kSphere, "\"matrix\":[1,0,0,0.1,0,1,0,0,0,0,1,0],", ""}}),
         "/leftChild/leftChild"},
        {"missing_radius", make_scene({{kSphere, ",\"radius\":1.5", ""}}), "/leftChild/leftChild"},
        {"missing_cylinder_height", make_scene({{kCylinder, "\"height\":3,", ""}}),
         "/leftChild/rightChild"},
        {"missing_sides", make_scene({{kBox, "\"sides\":[1,2,3],", ""}}), "/rightChild"},
        {"missing_primitive_type", make_scene({{kBox, "\"primitiveType\":\"box\",", ""}}),
         "/rightChild"},
        {"missing_left_child", make_scene({{kInner, "\"leftChild\":@SPHERE@,", "\"x\":@SPHERE@,"}}),
         "/leftChild"},
        {"missing_right_child", make_scene({{kRoot, ",\"rightChild\":@BOX@", ",\"other\":@BOX@"}}),
         "/"},
        {"missing_blend_mode", make_scene({{kRoot, "\"blendMode\":\"union\",", ""}}), "/"},
        {"missing_blend_radius", make_scene({{kInner, "\"blendRadius\":0.05,", ""}}), "/leftChild"},
        {"missing_aabb_min", make_scene({{kRoot, "\"aabb_min\":[-2,-2,-2],", ""}}), "/"},
        {"missing_aabb_max", make_scene({{kRoot, "\"aabb_max\":[2,2,2],", ""}}), "/"},
        // Unknown names.
        {"unknown_primitive_type",
         make_scene({{kBox, "\"primitiveType\":\"box\"", "\"primitiveType\":\"blob\""}}),
         "/rightChild/primitiveType"},
        {"unknown_blend_mode",
         make_scene({{kInner, "\"blendMode\":\"sub\"", "\"blendMode\":\"xor\""}}),
         "/leftChild/blendMode"},
        {"unknown_node_type",
         make_scene({{kCylinder, "\"nodeType\":\"primitive\"", "\"nodeType\":\"leaf\""}}),
         "/leftChild/rightChild/nodeType"},
        // Invalid values.
        {"negative_radius", make_scene({{kSphere, "\"radius\":1.5", "\"radius\":-1"}}),
         "/leftChild/leftChild"},
        {"zero_radius", make_scene({{kSphere, "\"radius\":1.5", "\"radius\":0"}}),
         "/leftChild/leftChild"},
        {"zero_cylinder_radius", make_scene({{kCylinder, "\"radius\":0.25", "\"radius\":0"}}),
         "/leftChild/rightChild"},
        {"zero_box_side", make_scene({{kBox, "\"sides\":[1,2,3]", "\"sides\":[1,0,3]"}}),
         "/rightChild"},
        {"negative_bevel",
         make_scene({{kBox, "\"bevel\":[0.1,0.1,0.1,0.1]", "\"bevel\":[0.1,-0.1,0.1,0.1]"}}),
         "/rightChild"},
        // Unequal radii beyond the half side they meet across make the field jump (found by
        // fuzz/fuzz_prune_eval.cpp: pruning was then wrong); equal ones stay continuous.
        {"unequal_bevel_beyond_half_side",
         make_scene({{kBox, "\"bevel\":[0.1,0.1,0.1,0.1]", "\"bevel\":[0.6,0.1,0.1,0.1]"}}),
         "/rightChild"},
        {"unequal_rounding_beyond_half_height",
         make_scene({{kBox, "\"round_x\":0.05", "\"round_x\":1.5"}}), "/rightChild"},
        {"negative_blend_radius",
         make_scene({{kInner, "\"blendRadius\":0.05", "\"blendRadius\":-0.1"}}), "/leftChild"},
        {"color_out_of_range", make_scene({{kSphere, "\"color\":[1,0,0]", "\"color\":[2,0,0]"}}),
         "/leftChild/leftChild"},
        // Numbers that are not finite floats.
        {"number_too_big_for_double", make_scene({{kSphere, "\"radius\":1.5", "\"radius\":1e999"}}),
         ""},
        {"number_overflows_float", make_scene({{kSphere, "\"radius\":1.5", "\"radius\":1e39"}}),
         "/leftChild/leftChild/radius"},
        {"matrix_entry_overflows_float",
         make_scene({{kBox, "[1,0,0,0,0,1,0,0.2,", "[1,0,0,0,0,1,0,-1e39,"}}),
         "/rightChild/matrix"},
        {"nan_literal", make_scene({{kSphere, "\"radius\":1.5", "\"radius\":NaN"}}), ""},
        {"infinity_literal", make_scene({{kSphere, "\"radius\":1.5", "\"radius\":Infinity"}}), ""},
        // Bounds.
        {"inverted_aabb",
         make_scene({{kRoot, "\"aabb_min\":[-2,-2,-2],\"aabb_max\":[2,2,2]",
                      "\"aabb_min\":[2,2,2],\"aabb_max\":[-2,-2,-2]"}}),
         ""},
        {"degenerate_aabb", make_scene({{kRoot, "\"aabb_max\":[2,2,2]", "\"aabb_max\":[2,-2,2]"}}),
         ""},
        {"aabb_with_two_entries",
         make_scene({{kRoot, "\"aabb_min\":[-2,-2,-2]", "\"aabb_min\":[-2,-2]"}}), "/aabb_min"},
        // Matrices.
        {"matrix_with_11_entries",
         make_scene({{kCylinder, "[1,0,0,0,0,1,0,0.3,0,0,1,0]", "[1,0,0,0,0,1,0,0.3,0,0,1]"}}),
         "/leftChild/rightChild/matrix"},
        {"matrix_with_13_entries",
         make_scene({{kCylinder, "[1,0,0,0,0,1,0,0.3,0,0,1,0]", "[1,0,0,0,0,1,0,0.3,0,0,1,0,0]"}}),
         "/leftChild/rightChild/matrix"},
        {"singular_matrix",
         make_scene({{kBox, "[1,0,0,0,0,1,0,0.2,0,0,1,0]", "[0,0,0,0,0,0,0,0,0,0,0,0]"}}),
         "/rightChild"},
        {"rank_two_matrix",
         make_scene({{kBox, "[1,0,0,0,0,1,0,0.2,0,0,1,0]", "[1,0,0,0,0,1,0,0.2,0,0,0,0]"}}),
         "/rightChild"},
        // Structure.
        {"duplicate_field",
         make_scene({{kSphere, "\"radius\":1.5", "\"radius\":1.5,\"radius\":2"}}),
         "/leftChild/leftChild"},
        {"duplicate_child",
         make_scene({{kRoot, ",\"rightChild\":@BOX@", ",\"rightChild\":@BOX@,\"rightChild\":{}"}}),
         "/"},
    };
    return c;
}

// gtest prints parameters in test listings; a case is known by its name.
void PrintTo(const Case& c, std::ostream* os) {
    *os << c.name;
}

class MalformedFile : public ::testing::TestWithParam<Case> {};

TEST_P(MalformedFile, ExitsWithOneLineNamingFileAndNode) {
    const Case& c = GetParam();
    const std::string path = write_temp(std::string(c.name) + ".json", c.text);
    const test::CliResult r = run_cli("info " + shell_quote(path));
    expect_one_line_error(r, path);
    if (!c.pointer.empty()) {
        EXPECT_NE(r.err.find(": " + c.pointer + ": "), std::string::npos)
            << "expected pointer " << c.pointer << " in: " << r.err;
    }
    EXPECT_EQ(r.out, "");
    // The library reports the same, as a SceneError.
    EXPECT_THROW(parse_scene(c.text, "x.json"), SceneError);
    std::remove(path.c_str());
}

INSTANTIATE_TEST_SUITE_P(All, MalformedFile, ::testing::ValuesIn(malformed_cases()),
                         [](const ::testing::TestParamInfo<Case>& info) {
                             return info.param.name;
                         });

TEST(MalformedInput, NodePointerInMessageMatchesLibrary) {
    // The message format: "<file>: <pointer>: <reason>".
    try {
        parse_scene(make_scene({{kCylinder, "\"radius\":0.25", "\"radius\":-3"}}), "scene.json");
        FAIL() << "accepted a negative radius";
    } catch (const SceneError& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind("scene.json: /leftChild/rightChild: ", 0), 0u) << what;
        EXPECT_NE(what.find("radius"), std::string::npos) << what;
        EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
}

TEST(MalformedInput, DeepPathsAreElidedToOneShortLine) {
    // An error 2000 levels down a left-deep chain: the pointer is shortened, still one line.
    std::string text;
    for (int i = 0; i < 2000; ++i)
        text +=
            std::string(R"({"nodeType":"binaryOperator","blendMode":"union","blendRadius":0,)") +
            (i == 0 ? R"("aabb_min":[-1,-1,-1],"aabb_max":[1,1,1],)" : "") +
            R"("matrix":[1,0,0,0,0,1,0,0,0,0,1,0],"leftChild":)";
    const std::string sphere =
        R"({"nodeType":"primitive","primitiveType":"sphere","matrix":[1,0,0,0,0,1,0,0,0,0,1,0],"radius":)";
    text += sphere + "-1}";
    for (int i = 0; i < 2000; ++i) text += ",\"rightChild\":" + sphere + "1}}";
    const std::string path = write_temp("deep_error.json", text);
    const test::CliResult r = run_cli("info " + shell_quote(path));
    expect_one_line_error(r, path);
    EXPECT_NE(r.err.find("/leftChild/leftChild"), std::string::npos) << r.err;
    EXPECT_LT(r.err.size(), 400u) << r.err;
    std::remove(path.c_str());
}

// ---- absurd nesting: refused quickly, in bounded memory ----------------------------------------

constexpr size_t kAbsurdDepth = 5'000'000;

void expect_nesting_refused(const std::string& name, const std::string& text) {
    const std::string path = write_temp(name, text);
    const auto start = std::chrono::steady_clock::now();
    const test::CliResult r = run_cli("info " + shell_quote(path));
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    expect_one_line_error(r, path);
    EXPECT_LT(seconds, 20.0);
    std::remove(path.c_str());
    EXPECT_THROW(parse_scene(text, name), SceneError);
}

TEST(MalformedInput, AbsurdlyDeepArraysAreRefused) {
    static_assert(kAbsurdDepth > kMaxJsonDepth);
    std::string text = make_scene({{kRoot, "\"blendRadius\":0.1,",
                                    "\"blendRadius\":0.1,\"extra\":"
                                    "@NEST@,"}});
    replace_once(text, "@NEST@", std::string(kAbsurdDepth, '[') + std::string(kAbsurdDepth, ']'));
    expect_nesting_refused("deep_arrays.json", text);
}

TEST(MalformedInput, AbsurdlyDeepObjectsAreRefused) {
    std::string nest;
    nest.reserve(kAbsurdDepth * 7);
    for (size_t i = 0; i < kAbsurdDepth; ++i) nest += "{\"a\":";
    nest += "0";
    nest.append(kAbsurdDepth, '}');
    std::string text = make_scene({{kBox, "\"round_y\":0", "\"round_y\":0,\"extra\":@NEST@"}});
    replace_once(text, "@NEST@", nest);
    expect_nesting_refused("deep_objects.json", text);
}

TEST(MalformedInput, NestingWithinTheLimitInUnknownFieldsIsSkipped) {
    // 100,000 levels of arrays and objects in an unknown field: ignored, the scene loads.
    std::string nest = std::string(50'000, '[');
    for (int i = 0; i < 50'000; ++i) nest += "{\"k\":";
    nest += "null";
    nest.append(50'000, '}');
    nest.append(50'000, ']');
    std::string text = make_scene({{kSphere, "\"radius\":1.5", "\"radius\":1.5,\"deep\":@NEST@"}});
    replace_once(text, "@NEST@", nest);
    EXPECT_EQ(parse_scene(text, "deep_ok.json").size(), 5u);
}

// ---- files that are not there ------------------------------------------------------------------

TEST(MalformedInput, NonexistentFile) {
    const std::string path = temp_path("no_such_dir/none.json");
    const test::CliResult r = run_cli("info " + shell_quote(path));
    expect_one_line_error(r, path);
    EXPECT_THROW(load_scene(path), SceneError);
}

TEST(MalformedInput, DirectoryPath) {
    std::string dir = ::testing::TempDir();
    while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
    const test::CliResult r = run_cli("info " + shell_quote(dir));
    expect_one_line_error(r, dir);
    EXPECT_THROW(load_scene(dir), SceneError);
}

// ---- what must be accepted ---------------------------------------------------------------------

TEST(MalformedInput, UnknownExtraFieldsAreAccepted) {
    const std::string extra =
        R"("comment":"made by hand","tags":["a",{"b":[1,2,{"c":null}]},true,false,null,1e300],"version":3,)";
    const std::string text = make_scene({{kRoot, "\"nodeType\"", extra + "\"nodeType\""},
                                         {kInner, "\"nodeType\"", extra + "\"nodeType\""},
                                         {kSphere, "\"nodeType\"", extra + "\"nodeType\""},
                                         {kCylinder, "\"nodeType\"", extra + "\"nodeType\""},
                                         {kBox, "\"round_y\":0", "\"round_y\":0,\"x\":{}"}});
    const std::string path = write_temp("extra_fields.json", text);
    const test::CliResult r = run_cli("info " + shell_quote(path));
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_EQ(r.err, "");
    // The extra fields change nothing.
    const Scene with = load_scene(path), without = parse_scene(make_scene(), "base.json");
    ASSERT_EQ(with.size(), without.size());
    for (float x = -1.5f; x <= 1.5f; x += 0.25f)
        EXPECT_EQ(eval_point(with, {x, 0.3f, -0.2f}), eval_point(without, {x, 0.3f, -0.2f}));
    std::remove(path.c_str());
}

TEST(MalformedInput, InfoJsonPrintsOneObjectOnTheLastLine) {
    const std::string path = write_temp("info_json.json", make_scene());
    const test::CliResult r = run_cli("info " + shell_quote(path) + " --json");
    ASSERT_EQ(r.status, 0) << r.err;
    ASSERT_FALSE(r.out.empty());
    ASSERT_EQ(r.out.back(), '\n');
    const std::string body = r.out.substr(0, r.out.size() - 1);
    const std::string last =
        body.substr(body.rfind('\n') == std::string::npos ? 0 : body.rfind('\n') + 1);
    rapidjson::Document d;
    d.Parse(last.c_str());  // fails on anything after the one object
    ASSERT_FALSE(d.HasParseError()) << last;
    ASSERT_TRUE(d.IsObject()) << last;
    for (const char* key : {"nodes", "primitives", "operators", "depth", "max_lipschitz"}) {
        ASSERT_TRUE(d.HasMember(key)) << key;
        EXPECT_TRUE(d[key].IsNumber()) << key;
    }
    EXPECT_EQ(d["nodes"].GetDouble(), 5);
    EXPECT_EQ(d["primitives"].GetDouble(), 3);
    EXPECT_EQ(d["operators"].GetDouble(), 2);
    EXPECT_EQ(d["depth"].GetDouble(), 2);
    EXPECT_EQ(d["max_lipschitz"].GetDouble(), 1);
    for (const auto& [key, value] : {std::pair{"aabb_min", -2.0}, std::pair{"aabb_max", 2.0}}) {
        ASSERT_TRUE(d.HasMember(key) && d[key].IsArray() && d[key].Size() == 3) << key;
        for (int i = 0; i < 3; ++i) EXPECT_EQ(d[key][i].GetDouble(), value) << key;
    }
    std::remove(path.c_str());
}

TEST(MalformedInput, BadCommandLines) {
    const std::string path = write_temp("args.json", make_scene());
    EXPECT_EQ(run_cli("info --bogus x").status, 2);
    EXPECT_EQ(run_cli("info " + shell_quote(path) + " --bogus").status, 2);
    EXPECT_EQ(run_cli("info").status, 2);
    EXPECT_EQ(run_cli("").status, 2);
    EXPECT_EQ(run_cli("no-such-command").status, 2);
    EXPECT_EQ(run_cli("info " + shell_quote(path)).status, 0);
    std::remove(path.c_str());
}

}  // namespace
}  // namespace sdfprune
