#include "tests/test_support.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include "core/base/error.h"

namespace rcb::test {

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

}  // namespace rcb::test
