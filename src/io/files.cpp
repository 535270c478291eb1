// files.cpp — whole-file reads and atomic writes (temporary file beside the target, then
// rename), so an interrupted or failed write never leaves a half-written output.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "sdfprune/io.hpp"

namespace sdfprune {
namespace {

std::string directory_of(const std::string& path) {
    std::filesystem::path p(path);
    std::filesystem::path dir = p.parent_path();
    return dir.empty() ? "." : dir.string();
}

}  // namespace

std::string read_file(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0)
        throw IoError(path + ": cannot open: " + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) throw IoError(path + ": is a directory");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IoError(path + ": cannot open: " + std::strerror(errno));
    std::string text;
    if (st.st_size > 0) text.reserve(size_t(st.st_size));
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    if (in.bad()) throw IoError(path + ": read error");
    return text;
}

void check_writable(const std::string& path) {
    if (path.empty()) throw IoError("output path is empty");
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
        throw IoError(path + ": is a directory");
    const std::string dir = directory_of(path);
    if (::stat(dir.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
        throw IoError(path + ": directory " + dir + " does not exist");
    if (::access(dir.c_str(), W_OK) != 0)
        throw IoError(path + ": directory " + dir + " is not writable");
}

void write_file_atomic(const std::string& path, std::string_view bytes) {
    check_writable(path);
    std::string tmp = path + ".tmp-XXXXXX";
    const int fd = ::mkstemp(tmp.data());
    if (fd < 0) throw IoError(path + ": cannot create: " + std::strerror(errno));
    size_t done = 0;
    while (done < bytes.size()) {
        const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
        if (n < 0) {
            if (errno == EINTR) continue;
            const std::string why = std::strerror(errno);
            ::close(fd);
            ::unlink(tmp.c_str());
            throw IoError(path + ": write failed: " + why);
        }
        done += size_t(n);
    }
    // mkstemp creates 0600; outputs get the usual permissions.
    ::fchmod(fd, 0644);
    if (::close(fd) != 0 || ::rename(tmp.c_str(), path.c_str()) != 0) {
        const std::string why = std::strerror(errno);
        ::unlink(tmp.c_str());
        throw IoError(path + ": cannot write: " + why);
    }
}

void write_atomic_with(const std::string& path,
                       const std::function<void(const std::string&)>& write) {
    check_writable(path);
    std::string tmp = path + ".tmp-XXXXXX";
    const int fd = ::mkstemp(tmp.data());
    if (fd < 0) throw IoError(path + ": cannot create: " + std::strerror(errno));
    ::close(fd);
    try {
        write(tmp);
    } catch (...) {
        ::unlink(tmp.c_str());
        throw;
    }
    ::chmod(tmp.c_str(), 0644);
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
        const std::string why = std::strerror(errno);
        ::unlink(tmp.c_str());
        throw IoError(path + ": cannot write: " + why);
    }
}

std::string extension_of(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

}  // namespace sdfprune
