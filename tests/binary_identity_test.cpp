// Which program made a run (runner/binary_identity.h): the build id read from the executable's ELF
// note, the name of the test program itself, runs stored before the record migrating as rcbench's,
// and a run resumed only by the program that began it.
#include <gtest/gtest.h>

#include <elf.h>

#include <cstring>
#include <string>
#include <vector>

#include "runner/binary_identity.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "tests/test_db.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

/// One ELF note as a linker writes it: header, name and descriptor, each padded to 4 bytes.
void append_note(std::vector<unsigned char>& out, std::uint32_t type, const std::string& name,
                 const std::vector<unsigned char>& desc) {
    const auto pad = [&] { out.resize((out.size() + 3) & ~std::size_t(3)); };
    Elf64_Nhdr h{std::uint32_t(name.size() + 1), std::uint32_t(desc.size()), type};
    const auto* bytes = reinterpret_cast<const unsigned char*>(&h);
    out.insert(out.end(), bytes, bytes + sizeof h);
    out.insert(out.end(), name.begin(), name.end());
    out.push_back(0);
    pad();
    out.insert(out.end(), desc.begin(), desc.end());
    pad();
}

TEST(BinaryIdentity, ReadsTheGnuBuildIdNoteAfterOthers) {
    std::vector<unsigned char> notes;
    append_note(notes, NT_GNU_ABI_TAG, "GNU", {0, 0, 0, 0, 3, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0});
    append_note(notes, NT_GNU_BUILD_ID, "Go", {1, 2, 3});  // another owner's note of the same type
    append_note(notes, NT_GNU_BUILD_ID, "GNU", {0xa6, 0xed, 0xb4, 0x53, 0x05});
    EXPECT_EQ(gnu_build_id(notes.data(), notes.size()), "a6edb45305");
    // A segment cut inside the build id's descriptor holds no build id; nor does one without it.
    EXPECT_EQ(gnu_build_id(notes.data(), notes.size() - 4), "");
    EXPECT_EQ(gnu_build_id(notes.data(), 32), "");
    EXPECT_EQ(gnu_build_id(notes.data(), 0), "");
}

TEST(BinaryIdentity, NamesTheRunningProgramAndItsLinkersBuildId) {
    const BinaryIdentity& me = this_binary();
    EXPECT_EQ(me.name, "rcb_tests");
    // Debian's GCC and clang link with --build-id (a SHA-1: 20 bytes); no fallback is needed here.
    EXPECT_EQ(me.build_id.size(), 40u) << me.build_id;
    EXPECT_EQ(me.build_id.find_first_not_of("0123456789abcdef"), std::string::npos) << me.build_id;
}

TEST(BinaryIdentity, RunsStoredBeforeTheRecordAreRcbenchsAndNewRunsNameTheirProgram) {
    const test::TempDir dir("binary", "migrate");
    const std::string path = dir.file("old.db");
    {
        ResultStore old(path, latest_schema_version() - 1);
        old.db().exec(
            "INSERT INTO experiment(name) VALUES ('e');"
            "INSERT INTO run(uuid, experiment_id, experiment_hash, experiment_content, started_at, git_commit, "
            "compiler, flags, cpu_model, cores, governor, hostname, threads, shard) "
            "VALUES ('u', 1, 'h', '{}', 't', 'g', 'c', 'f', 'cpu', 1, 'gov', 'host', 1, '');");
    }
    ResultStore store(path);  // migrated on open
    EXPECT_EQ(test::count(store.db(), "SELECT count(*) FROM run WHERE binary = 'rcbench' AND binary_id = ''"), 1);
    Experiment e;
    e.name = "e";
    e.hash = "h";
    e.content = "{}";
    const std::int64_t run = store.begin_run(store.experiment_id(e), RunInfo::current(1, "", e));
    EXPECT_EQ(store.run_binary(run), "rcb_tests");
    EXPECT_EQ(test::count(store.db(), "SELECT count(*) FROM run WHERE binary_id = '" + this_binary().build_id + "'"),
              1);
    EXPECT_EQ(store.run_binary(99), std::nullopt);
}

TEST(BinaryIdentity, ARunResumesOnlyInTheProgramThatBeganIt) {
    const test::TempDir dir("binary", "resume");
    ResultStore store(dir.file("r.db"));
    Experiment e;
    e.name = "e";
    e.hash = "h";
    e.content = "{}";
    RunInfo engine = RunInfo::current(1, "", e);
    engine.binary = "engine_bench";
    const std::int64_t first = store.resume_or_begin_run(e, engine, false);  // left unfinished
    const std::int64_t mine = store.resume_or_begin_run(e, RunInfo::current(1, "", e), false);
    EXPECT_NE(mine, first);                                         // rcb_tests does not take the engine's run
    EXPECT_EQ(store.resume_or_begin_run(e, engine, false), first);  // the engine resumes its own
    EXPECT_EQ(store.resume_or_begin_run(e, RunInfo::current(1, "", e), false), mine);
    // Named with --run, another program's run is refused in one line.
    RunOptions options;
    options.db = dir.file("r.db");
    options.run_id = first;
    test::expect_input_error([&] { run_experiment(e, "e.json", options, {}); },
                             "--run 1: a run of engine_bench, not of rcb_tests (a run is resumed by the program that "
                             "began it)");
}

}  // namespace
}  // namespace rcb
