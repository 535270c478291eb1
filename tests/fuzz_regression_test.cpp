// fuzz_regression_test.cpp — every file of fuzz/regressions/<target>/ (inputs the fuzzers once
// broke the library with) and of the seed corpus fuzz/corpus/<target>/ through the fuzz targets'
// own entry points (fuzz/fuzz_entry.hpp): each must be accepted or refused with the documented
// error type, never crash, hang or break a checked property.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz/fuzz_entry.hpp"

namespace sdfprune {
namespace {

namespace fs = std::filesystem;
using fuzz::Outcome;

using Entry = Outcome (*)(std::span<const uint8_t>);

std::vector<fs::path> files_in(const fs::path& dir) {
    std::vector<fs::path> files;
    if (fs::is_directory(dir))
        for (const fs::directory_entry& e : fs::directory_iterator(dir))
            if (e.is_regular_file()) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    return files;
}

std::vector<uint8_t> read_bytes(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

struct Counts {
    size_t files = 0, accepted = 0;
};

// Runs `entry` over every file of `dir`; any exception (FuzzPropertyViolation or an
// undocumented type) fails the test naming the file.
Counts run_all(Entry entry, const fs::path& dir) {
    Counts c;
    for (const fs::path& f : files_in(dir)) {
        const std::vector<uint8_t> bytes = read_bytes(f);
        ++c.files;
        try {
            if (entry(bytes) == Outcome::kAccepted) ++c.accepted;
        } catch (const std::exception& e) {
            ADD_FAILURE() << f << ": " << e.what();
        } catch (...) {
            ADD_FAILURE() << f << ": a non-standard exception";
        }
    }
    return c;
}

struct Target {
    const char* name;
    Entry entry;
};

const Target kTargets[] = {
    {"scene_loader", fuzz::scene_loader},
    {"npy_reader", fuzz::npy_reader},
    {"prune_eval", fuzz::prune_eval},
};

class FuzzRegression : public ::testing::TestWithParam<Target> {};

TEST_P(FuzzRegression, RegressionsAreHandled) {
    const Counts c =
        run_all(GetParam().entry, fs::path(SDFPRUNE_FUZZ_DIR) / "regressions" / GetParam().name);
    RecordProperty("files", std::to_string(c.files));
}

TEST_P(FuzzRegression, SeedCorpusIsHandled) {
    const Counts c =
        run_all(GetParam().entry, fs::path(SDFPRUNE_FUZZ_DIR) / "corpus" / GetParam().name);
    // The corpus is committed (fuzz/make_corpus.py) and mostly valid input.
    EXPECT_GE(c.files, 10u);
    EXPECT_GE(c.accepted * 2, c.files);
}

INSTANTIATE_TEST_SUITE_P(Fuzz, FuzzRegression, ::testing::ValuesIn(kTargets),
                         [](const auto& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace sdfprune
