#include "core/base/output_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "core/base/error.h"

namespace rcb {
namespace fs = std::filesystem;

namespace {

/// Where a write to `path` lands: through a symbolic link, the file it names, not the link.
fs::path write_target(const std::string& path) {
    std::error_code ec;
    return fs::is_symlink(path, ec) ? fs::weakly_canonical(path, ec) : fs::absolute(path, ec);
}

}  // namespace

bool same_file(const std::string& a, const std::string& b) {
    std::error_code ec;
    if (fs::exists(a, ec) && fs::exists(b, ec)) return fs::equivalent(a, b, ec) && !ec;
    const fs::path pa = fs::weakly_canonical(fs::absolute(a, ec), ec),
                   pb = fs::weakly_canonical(fs::absolute(b, ec), ec);
    return pa == pb;
}

void check_output_path(const std::string& path, const std::vector<std::string>& inputs, const std::string& option) {
    const std::string where = option.empty() ? path : option + " " + path;
    if (path.empty()) throw InputError(option + ": empty output path");
    std::error_code ec;
    if (fs::is_directory(path, ec)) throw InputError(where + ": is a directory; name a file");
    for (const std::string& input : inputs)
        if (!input.empty() && same_file(path, input))
            throw InputError(where + ": is also an input of this command (" + input + "); name another output file");
    if (fs::exists(path, ec) && !fs::is_regular_file(path, ec)) return;  // a device or pipe: written in place
    // Probe the folder with the kind of temporary file the write will use, so an unwritable place
    // (a read-only folder, /proc) fails now rather than after the work.
    const fs::path folder = write_target(path).parent_path();
    fs::create_directories(folder, ec);
    std::string probe = (folder / ".rcbench-probe.XXXXXX").string();
    const int fd = ::mkstemp(probe.data());
    if (fd < 0) throw InputError(where + ": cannot write in " + folder.string() + " (" + std::strerror(errno) + ")");
    ::close(fd);
    ::unlink(probe.c_str());
}

namespace {

/// Closes a descriptor and removes the temporary file unless released.
struct TempFile {
    int fd = -1;
    std::string path;
    ~TempFile() {
        if (fd >= 0) ::close(fd);
        if (!path.empty()) ::unlink(path.c_str());
    }
};

/// A new hidden file beside `target`, unique in its folder, open for writing (mode 0644); its path
/// goes to `made`. InputError naming `path` when the folder cannot be written.
int make_temporary(const fs::path& target, const std::string& path, std::string& made) {
    std::error_code ec;
    fs::create_directories(target.parent_path(), ec);  // a failure shows as mkstemp's below
    // Hidden, unique per process, in the target's folder (rename is atomic within one file system).
    // ("dir/." then the name: GCC 12 warns falsely, -Wrestrict, on "." + std::string&&.)
    std::string pattern = (target.parent_path() / ".").concat(target.filename().string() + ".XXXXXX").string();
    const int fd = ::mkstemp(pattern.data());
    if (fd < 0) throw InputError(path + ": cannot write here (" + std::strerror(errno) + ")");
    ::fchmod(fd, 0644);
    made = pattern;
    return fd;
}

void write_all(int fd, std::string_view bytes, const std::string& path) {
    for (std::size_t done = 0; done < bytes.size();) {
        const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) throw std::runtime_error(path + ": write failed (" + std::strerror(errno) + ")");
        done += std::size_t(n);
    }
}

}  // namespace

void write_file_atomically(const std::string& path, std::string_view bytes) {
    std::error_code ec;
    if (fs::is_directory(path, ec)) throw InputError(path + ": is a directory; name a file");
    if (fs::exists(path, ec) && !fs::is_regular_file(path, ec)) {
        // A device or pipe (/dev/stdout, a FIFO): there is no file to replace, so write into it.
        const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
        if (fd < 0) throw InputError(path + ": cannot open for writing (" + std::strerror(errno) + ")");
        TempFile guard{fd, ""};
        write_all(fd, bytes, path);
        return;
    }
    const fs::path target = write_target(path);
    TempFile tmp;
    tmp.fd = make_temporary(target, path, tmp.path);
    write_all(tmp.fd, bytes, path);
    if (::fsync(tmp.fd) != 0 && errno != EINVAL)
        throw std::runtime_error(path + ": write failed (" + std::strerror(errno) + ")");
    if (::close(tmp.fd) != 0) {
        tmp.fd = -1;
        throw std::runtime_error(path + ": write failed (" + std::strerror(errno) + ")");
    }
    tmp.fd = -1;
    if (::rename(tmp.path.c_str(), target.c_str()) != 0)
        throw InputError(path + ": cannot replace it (" + std::strerror(errno) + ")");
    tmp.path.clear();
}

std::string create_temporary_file_for(const std::string& path) {
    std::string made;
    ::close(make_temporary(write_target(path), path, made));
    return made;
}

void replace_with_temporary_file(const std::string& temporary, const std::string& path) {
    if (::rename(temporary.c_str(), write_target(path).c_str()) != 0)
        throw InputError(path + ": cannot replace it (" + std::strerror(errno) + ")");
}

}  // namespace rcb
