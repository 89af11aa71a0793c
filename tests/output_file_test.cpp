// Output files: written whole or not at all, never over an input, never through a directory.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/base/error.h"
#include "core/base/output_file.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

class OutputFile : public ::testing::Test {
protected:
    std::string path(const std::string& name) const { return dir_.file(name); }
    static std::string read(const std::string& p) {
        std::ifstream in(p, std::ios::binary);
        std::ostringstream s;
        s << in.rdbuf();
        return s.str();
    }
    std::size_t entries() const {
        return std::size_t(std::distance(fs::directory_iterator(dir_.path()), fs::directory_iterator()));
    }
    test::TempDir dir_{"out"};  // rcb_out_<pid>_<test>, removed after the test
};

TEST_F(OutputFile, ReplacesTheFileWholeAndLeavesNoTemporaryFile) {
    std::ofstream(path("a.txt")) << "old";
    write_file_atomically(path("a.txt"), "new contents");
    EXPECT_EQ(read(path("a.txt")), "new contents");
    EXPECT_EQ(entries(), 1u);
}

TEST_F(OutputFile, CreatesMissingFolders) {
    write_file_atomically(path("x/y/z.txt"), "deep");
    EXPECT_EQ(read(path("x/y/z.txt")), "deep");
}

TEST_F(OutputFile, RefusesADirectoryAndLeavesNothingBeside) {
    fs::create_directories(path("d"));
    EXPECT_THROW(check_output_path(path("d"), {}, "-o"), InputError);
    EXPECT_THROW(write_file_atomically(path("d"), "x"), InputError);
    EXPECT_EQ(entries(), 1u);  // no "d.tmp"
}

TEST_F(OutputFile, RefusesAnInputUnderAnySpelling) {
    std::ofstream(path("res.db")) << "database";
    fs::create_symlink(path("res.db"), path("link.db"));
    const std::string relative = fs::relative(path("res.db"), fs::current_path()).string();
    for (const std::string& out : {path("res.db"), path("link.db"), path("./res.db"), relative}) {
        SCOPED_TRACE(out);
        test::expect_input_error([&] { check_output_path(out, {path("res.db")}, "-o"); }, "is also an input");
    }
    EXPECT_NO_THROW(check_output_path(path("report.html"), {path("res.db")}, "-o"));
    EXPECT_EQ(read(path("res.db")), "database");
}

TEST_F(OutputFile, WritesThroughASymlinkToTheFileItNames) {
    std::ofstream(path("real.txt")) << "old";
    fs::create_symlink(path("real.txt"), path("link.txt"));
    write_file_atomically(path("link.txt"), "new");
    EXPECT_TRUE(fs::is_symlink(path("link.txt")));
    EXPECT_EQ(read(path("real.txt")), "new");
}

TEST_F(OutputFile, AnUnwritablePlaceFailsBeforeTheWork) {
    EXPECT_THROW(check_output_path("/proc/self/out.md", {}, "--out-dir"), InputError);
}

TEST_F(OutputFile, AWriteErrorIsReportedNotIgnored) {
    // /dev/full is a device: written in place (not replaced), and every write fails with ENOSPC.
    EXPECT_NO_THROW(check_output_path("/dev/full", {}, "--json-out"));
    EXPECT_THROW(write_file_atomically("/dev/full", "lines"), std::runtime_error);
    EXPECT_TRUE(fs::is_character_file("/dev/full"));
}

}  // namespace
}  // namespace rcb
