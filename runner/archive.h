#pragma once
/// The results archive (results/archive/): compact, compressed exports of results databases, the
/// data behind every figure in docs/, each with a manifest that records where it came from.
///
/// An export is an rcbench results database at the latest schema, so every reading command (`fit`,
/// `validate`, `findings`, `compare`, `query`, `report`) reads it after one unpacking step. It keeps
/// every table and every frame (fit and validate take each measured frame as an observation,
/// compare's U test the frames, findings per-frame medians) and drops only `frame.stats`, the
/// structure's own statistics after each frame, which no command reads back and which is most of a
/// database's bytes. Compressed with xz (liblzma): about half of gzip's size on these files, and
/// `xz -d` unpacks it as well as `rcbench archive unpack`.
///
/// Archived data is added to, never edited: adding refuses a name the archive holds, and
/// verify_archive checks every export against the SHA-256 its manifest recorded.

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace rcb {

/// SHA-256 (FIPS 180-4) of bytes, as 64 lowercase hex digits.
std::string sha256_hex(std::string_view bytes);
/// SHA-256 of a file's bytes; InputError naming the file if it cannot be read.
std::string sha256_file(const std::filesystem::path& path);

/// Compresses `in` into a new .xz file `out` (preset 6, CRC64 check: what `xz` writes by default).
void xz_compress_file(const std::filesystem::path& in, const std::filesystem::path& out);
/// Decompresses the .xz file `in` into a new file `out`; InputError naming `in` if it is not xz data.
void xz_decompress_file(const std::filesystem::path& in, const std::filesystem::path& out);

struct ArchiveRequest {
    std::string source;   ///< the results database to export
    std::string name;     ///< the export's name: NAME.db.xz and NAME.json in `archive_dir`
    std::string command;  ///< the command that made the source's runs, as it was typed
    std::filesystem::path archive_dir = "results/archive";
    bool allow_dirty = false;  ///< archive runs built from a dirty tree, marked so in the manifest
};

/// Writes ARCHIVE/NAME.db.xz and ARCHIVE/NAME.json and returns the manifest. Refuses (InputError,
/// nothing written) a name the archive holds, a name that is not [A-Za-z0-9][A-Za-z0-9._-]*, a
/// source without runs or damaged, and, unless allow_dirty, a run whose binary was built from a
/// dirty or unknown tree.
nlohmann::json add_to_archive(const ArchiveRequest& request);

/// The manifest of an export (the .json beside ARCHIVE/NAME.db.xz); InputError if missing or unreadable.
nlohmann::json read_manifest(const std::filesystem::path& export_xz);

/// Unpacks an export into a new database file `out` after checking the compressed file's SHA-256
/// against its manifest, and the database's after unpacking. Refuses an existing `out`.
void unpack_export(const std::filesystem::path& export_xz, const std::filesystem::path& out);

/// Checks every export of an archive folder: each NAME.db.xz has its NAME.json and the reverse, and
/// each file's SHA-256 is the one its manifest recorded. Returns the manifests by name; InputError
/// naming the first export that fails.
std::vector<nlohmann::json> verify_archive(const std::filesystem::path& archive_dir);

}  // namespace rcb
