#pragma once
/// The recording file's pieces (the format: recording_io.h), shared by recording_io.cpp, which
/// writes and reads whole recordings, and recording_stream.cpp, which writes and reads them a frame
/// at a time (recording_stream.h): each section encoded alone, so that both write the same bytes,
/// and the reading side, which pulls sections one at a time and checks them as they come. For
/// rcbench's own readers and writers; an engine uses recording_io.h and recording_stream.h.

#include <cstddef>
#include <cstdint>
#include <fstream>
#include <istream>
#include <memory>
#include <sstream>
#include <string>
#include <unordered_set>
#include <vector>

#include "core/scene/scene.h"

namespace rcb::sections {

/// The lowest version that holds frame 0's objects: 2 when one has a shape.
std::uint32_t objects_version(const std::vector<Object>& objects);
/// The lowest version that holds one frame: 3 for a query kind other than `all`, 2 for a shape.
std::uint32_t frame_version(const Frame& frame);

/// The file's pieces at `version`, each encoded alone: encode_recording joins them,
/// RecordingWriter appends them one at a time.
std::string header_bytes(std::uint32_t version);
std::string meta_section(const std::string& meta);
std::string objects_section(const std::vector<Object>& objects, std::uint32_t version);
std::string frame_section(const Frame& frame, std::size_t number, std::uint32_t version);
std::string end_section();

/// InputError "<path>: cannot open for writing (no folder ...)" when the folder `path` would be
/// written in does not exist: the recording's writers write into a folder, never make one (an
/// engine's recorder whose folder went away writes nothing).
void refuse_missing_folder(const std::string& path);

/// "<name>: frame N": where a frame's errors say they are.
std::string frame_context(const std::string& name, std::size_t frame);
/// Refuses frame 0's objects (check_object, unique uids), naming `name` and frame 0; returns
/// their uids, the live set the frames are checked against.
std::unordered_set<Uid> refuse_invalid_initial(const std::vector<Object>& objects, const std::string& name);
/// Refuses one frame's changes, rays and query kinds against the live uid set (InputError naming
/// `context`), and applies its changes to it.
void refuse_invalid_frame(const Frame& frame, std::unordered_set<Uid>& live, const std::string& context);

class Decoder;  // bounds-checked little-endian reads of one section's bytes (recording_io.cpp)

/// The reading side: sections pulled one at a time from a file or from bytes in memory, checked
/// as they come. `unterminated` accepts a file that stops after a whole frame without END:
/// RecordingWriter's temporary file, read back to raise its version.
struct Reading {
    std::ifstream file;
    std::istringstream memory;
    std::istream* in = nullptr;
    std::uint64_t size = 0, pos = 0;
    std::string name;
    bool unterminated = false;

    std::uint32_t version = 0;
    std::string meta;
    std::vector<Object> initial;
    std::unordered_set<Uid> live;
    std::size_t frames_seen = 0;
    enum class Expect { meta, objs, frames, done } expect = Expect::meta;

    /// Up to n bytes from the current position (fewer at the end of the input).
    std::string take(std::uint64_t n);
    /// Reads the header, META and OBJS.
    void read_prologue();
    /// Reads one section; true when it was a frame (put in `frame`), false for META, OBJS and END.
    bool section(Frame* frame);

    // section()'s parts.
    void read_header();
    void read_objects(Decoder& p, const std::string& where);
    void read_frame(Decoder& p, std::uint64_t length, const std::string& where, Frame& f);
};

/// A reading of the file at `path`, nothing read yet. InputError for a folder or a file that
/// cannot be opened.
std::unique_ptr<Reading> open_reading(const std::string& path, bool unterminated);
/// A reading of `bytes` in memory, errors naming `name`.
std::unique_ptr<Reading> memory_reading(const std::string& bytes, const std::string& name);

}  // namespace rcb::sections
