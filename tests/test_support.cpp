#include "tests/test_support.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>

#include "core/base/error.h"

namespace rcb::test {

std::string input_error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

void expect_input_error(const std::function<void()>& f, const std::string& substring, const char* file, int line) {
    const std::string message = input_error_of(f);
    if (message.empty())
        ADD_FAILURE_AT(file, line) << "no InputError (expected one containing \"" << substring << "\")";
    else if (message.find(substring) == std::string::npos)
        ADD_FAILURE_AT(file, line) << "the InputError \"" << message << "\" does not contain \"" << substring << "\"";
}

std::filesystem::path temp_dir(const std::string& suite, const std::string& name) {
    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / ("rcb_" + suite + "_" + std::to_string(::getpid()) + "_" + name);
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    return dir;
}

TempDir::TempDir(const std::string& suite, const std::string& name) : path_(temp_dir(suite, name)) {}

TempDir::TempDir(const std::string& suite)
    : TempDir(suite, ::testing::UnitTest::GetInstance()->current_test_info()->name()) {}

TempDir::~TempDir() {
    std::error_code ignored;  // a destructor must not throw; a leftover folder fails nothing
    std::filesystem::remove_all(path_, ignored);
}

namespace {

/// A number in [lo, hi]: an end one time in four, else uniform or log-uniform (see random_params).
double random_in_range(const ParamSpec& p, Random& rng) {
    const std::uint64_t pick = rng.below(8);
    if (pick == 0) return p.lo;
    if (pick == 1) return p.hi;
    const bool integer = p.kind == ParamKind::integer;
    const bool wide = p.log_scale || p.hi >= 32 * std::max(p.lo, 1.0);
    if (!wide) return integer ? p.lo + double(rng.below(std::uint64_t(p.hi - p.lo) + 1)) : rng.uniform(p.lo, p.hi);
    if (integer) {
        const double lo = std::max(p.lo, 1.0);
        return std::min(p.hi, std::floor(rng.log_uniform(lo, p.hi + 1)));
    }
    return rng.log_uniform(p.lo > 0 ? p.lo : p.hi * 1e-4, p.hi);
}

nlohmann::json draw(const StructureInfo& info, Random& rng, const std::set<std::string>& keep_default) {
    nlohmann::json params = nlohmann::json::object();
    for (const ParamSpec& p : info.params) {
        if (rng.below(4) == 0 || keep_default.contains(p.name)) continue;  // its default
        switch (p.kind) {
            case ParamKind::boolean:
                params[p.name] = rng.below(2) == 1;
                break;
            case ParamKind::choice:
                params[p.name] = p.choices[rng.below(p.choices.size())];
                break;
            case ParamKind::integer:
                params[p.name] = std::int64_t(random_in_range(p, rng));
                break;
            case ParamKind::real:
                params[p.name] = random_in_range(p, rng);
                break;
        }
    }
    return params;
}

}  // namespace

nlohmann::json random_params(const StructureInfo& info, Random& rng, const std::set<std::string>& keep_default) {
    for (int attempt = 0; attempt < 100; ++attempt) {
        nlohmann::json params = draw(info, rng, keep_default);
        const std::string refused = input_error_of([&] { info.make(params, "params"); });
        if (refused.empty()) return params;
        // A refusal names the parameter path it refuses, as every bad input must.
        EXPECT_EQ(refused.rfind("params", 0), 0u) << info.name << ' ' << params.dump() << ": " << refused;
    }
    ADD_FAILURE() << info.name << ": 100 parameter sets drawn from its specs, every one refused";
    return nlohmann::json::object();
}

}  // namespace rcb::test
