// test_util.cpp — running the CLI from tests.
#include "test_util.hpp"

#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <sstream>

namespace sdfprune::test {

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

}  // namespace sdfprune::test
