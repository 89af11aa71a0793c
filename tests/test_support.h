#pragma once
/// Helpers every suite shares: the message of an InputError, temporary folders, and parameter sets
/// drawn at random from a registered structure's ParamSpecs.

#include <filesystem>
#include <functional>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "core/accel/registry.h"
#include "core/base/random.h"

namespace rcb::test {

/// The message of the InputError `f` throws, "" when it returns. Any other exception goes through
/// (gtest fails the test with it). The one place the suites catch an InputError: a test states
/// what the message must be (whole, prefix, substrings) on the string this returns.
std::string input_error_of(const std::function<void()>& f);

/// Expects `f` to throw an InputError whose message contains `substring`; a failure is reported at
/// the caller's line, with the message `f` threw or that it threw none. (__builtin_FILE and
/// __builtin_LINE, not std::source_location: clang 14 with libstdc++ 12 has no source_location.)
void expect_input_error(const std::function<void()>& f, const std::string& substring,
                        const char* file = __builtin_FILE(), int line = __builtin_LINE());

/// An empty folder rcb_<suite>_<pid>_<name> in the system's temporary folder (emptied if it
/// exists), for a test's databases and files.
std::filesystem::path temp_dir(const std::string& suite, const std::string& name);

/// temp_dir(suite, name) for the lifetime of the object, removed with its contents at the end
/// (also when an ASSERT leaves the test early). Without `name`, the running test's name.
class TempDir {
public:
    TempDir(const std::string& suite, const std::string& name);
    explicit TempDir(const std::string& suite);
    ~TempDir();
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;

    const std::filesystem::path& path() const { return path_; }
    /// The path of `name` inside the folder, as a string.
    std::string file(const std::string& name) const { return (path_ / name).string(); }

private:
    std::filesystem::path path_;
};

/// One parameter object for `info`, drawn from its ParamSpecs: each parameter is left at its default
/// one time in four, else drawn from its spec. Booleans and choices uniformly; integers and reals
/// at an end of their range one time in four, otherwise uniformly, or log-uniformly when the range
/// spans orders of magnitude (log_scale, or hi at least 32 times max(lo, 1); integers from
/// max(lo, 1), reals from hi / 10^4 when lo is 0), so "0: off" ends and small values both come up
/// in ranges as wide as 0..10^6. Combinations the structure refuses (an InputError from
/// `make`, e.g. query=candidates with a leaf volume) are drawn again. The parameters named in
/// `keep_default` stay at their defaults.
nlohmann::json random_params(const StructureInfo& info, Random& rng, const std::set<std::string>& keep_default = {});

}  // namespace rcb::test
