#pragma once
/// Writing the files a user asked for, and nothing else. Every output is written to a temporary file
/// beside it and renamed into place only when complete, so a failed command leaves an existing file
/// as it was; an output path that is a directory or names one of the command's inputs is refused
/// before any work is done (`report res.db -o res.db` must not replace the database).

#include <string>
#include <string_view>
#include <vector>

namespace rcb {

/// Whether two paths name the same file (the same inode when both exist, else the same normalised
/// absolute path).
bool same_file(const std::string& a, const std::string& b);

/// InputError, naming `option`, when `path` is empty, is a directory, or is the same file as one of
/// `inputs`. Call it before the work, so a bad output path costs nothing.
void check_output_path(const std::string& path, const std::vector<std::string>& inputs, const std::string& option);

/// Writes `bytes` to `path` atomically (temporary file in the same folder, flushed to disk, then
/// renamed over `path`), creating missing folders; the temporary file is removed on any failure. InputError when the
/// folder cannot be written (a bad output path), std::runtime_error when writing fails (disk full, I/O).
void write_file_atomically(const std::string& path, std::string_view bytes);

/// The temporary file write_file_atomically writes, for a writer that streams into it: a new
/// empty file in the folder of the file `path` names (missing folders created), hidden and of a
/// name unique there (mkstemp never opens a file that exists, so no file of the user's is ever
/// written over), mode 0644; returns its path. InputError when the folder cannot be written.
std::string create_temporary_file_for(const std::string& path);
/// Renames `temporary` (create_temporary_file_for's) over the file `path` names (through a
/// symbolic link, the file it names), as write_file_atomically does. InputError when it cannot.
void replace_with_temporary_file(const std::string& temporary, const std::string& path);

}  // namespace rcb
