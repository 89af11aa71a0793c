#pragma once
/// Which program wrote a run: rcbench, or a program that links rcbench::cli with its own
/// structures registered (cli/cli.h). Recorded with every run (run.binary, run.binary_id;
/// docs/database.md), so that a program's runs and rcbench's stay apart (history keeps a series per
/// binary, a run resumes only in the binary that began it) and stay comparable (compare names the
/// binaries of its two sides when they differ).

#include <cstddef>
#include <string>

namespace rcb {

struct BinaryIdentity {
    /// The executable's file name, from /proc/self/exe (not argv[0], which a caller may set to
    /// anything): "rcbench", or a program's own name.
    std::string name;
    /// The linker's build id of the executable (the ELF note NT_GNU_BUILD_ID, `readelf -n`, as gdb,
    /// perf and debuginfod identify a binary): a hash of the linked program, so it changes with any
    /// change to the code in it (the program's structures, rcbench's libraries, the flags) and is
    /// equal for bit-identical builds, with no file to read at run time. Where the linker wrote
    /// none, "fnv-" and stable_hash (runner/experiment.h) of the executable's bytes; "unknown" when
    /// neither can be read.
    std::string build_id;
};

/// The running program's identity, computed once.
const BinaryIdentity& this_binary();

/// The build id of an ELF note segment's contents (a PT_NOTE segment, `size` bytes at `notes`),
/// as lower-case hex; empty when the segment holds no GNU build-id note.
std::string gnu_build_id(const unsigned char* notes, std::size_t size);

}  // namespace rcb
