// test_util.cpp — running the CLI from tests, and each test process's own temporary directory.
#include "test_util.hpp"

#include <stdlib.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

#include "sdfprune/builder.hpp"

namespace sdfprune::test {
namespace {

// The files tests write (under ::testing::TempDir(), which reads TEST_TMPDIR) go to a directory
// of the test process's own, removed with everything in it when the process's tests end, so that
// no run leaves files behind in the system's temporary directory.
class OwnTempDir : public ::testing::Environment {
  public:
    void SetUp() override {
        namespace fs = std::filesystem;
        std::error_code ec;
        std::string pattern = (fs::temp_directory_path(ec) / "sdfprune_tests_XXXXXX").string();
        if (ec || ::mkdtemp(pattern.data()) == nullptr) return;  // TempDir() stays as it was
        dir_ = pattern;
        ::setenv("TEST_TMPDIR", dir_.c_str(), 1);
    }
    void TearDown() override {
        if (dir_.empty()) return;
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }

  private:
    std::string dir_;
};

[[maybe_unused]] const ::testing::Environment* const own_temp_dir =
    ::testing::AddGlobalTestEnvironment(new OwnTempDir);

}  // namespace

CliResult run_cli(const std::string& args, const std::string& env) {
    const std::string base = ::testing::TempDir() + "sdfprune_cli_" + std::to_string(::getpid());
    const std::string out = base + ".out", err = base + ".err";
    const std::string cmd =
        env + (env.empty() ? "" : " ") + SDFPRUNE_CLI + " " + args + " >" + out + " 2>" + err;
    CliResult r;
    const int raw = std::system(cmd.c_str());
    r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
    auto slurp = [](const std::string& path) {
        std::ifstream in(path);
        std::stringstream ss;
        ss << in.rdbuf();
        return ss.str();
    };
    r.out = slurp(out);
    r.err = slurp(err);
    std::remove(out.c_str());
    std::remove(err.c_str());
    return r;
}

size_t pixels_differing(const Image& a, const Image& b, int tolerance) {
    EXPECT_EQ(a.rgb.size(), b.rgb.size());
    const size_t n = std::min(a.rgb.size(), b.rgb.size());
    size_t differ = 0;
    for (size_t i = 0; i + 2 < n; i += 3) {
        int d = 0;
        for (int c = 0; c < 3; ++c)
            d = std::max(d, std::abs(int(a.rgb[i + c]) - int(b.rgb[i + c])));
        differ += d > tolerance;
    }
    return differ;
}

Scene grains_on_floor() {
    SceneBuilder b;
    Shape scene = b.box({1.6f, 0.2f, 1.6f});
    for (int i = 0; i < 12; ++i)
        for (int j = 0; j < 12; ++j) {
            const float r = 0.008f + 0.004f * float((i + j) % 3);
            const float gap = 0.004f + 0.008f * float((i * 5 + j) % 3);
            scene = scene | b.sphere(r).translated({-0.7f + 0.127f * float(i), 0.1f + r + gap,
                                                    -0.7f + 0.127f * float(j)});
        }
    return b.build(scene);
}

}  // namespace sdfprune::test
