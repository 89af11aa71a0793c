#pragma once
/// Scenes streamed frame by frame instead of held whole: a generator gives each frame to a
/// SceneSink as it makes it, RecordingWriter appends it to the file (the format: recording_io.h),
/// and RecordingReader reads a file back one frame at a time. A recording of any length is then
/// made and written in the memory of one frame; the bytes are write_recording's.

#include <cstdint>
#include <fstream>
#include <memory>
#include <string>
#include <unordered_set>
#include <vector>

#include "core/scene/recording_io.h"
#include "core/scene/scene.h"

namespace rcb {

namespace sections {
struct Reading;  // recording_sections.h
}  // namespace sections

/// Where a scene goes as a generator makes it: the meta and frame 0's objects once, then each
/// frame in order (numbered 1, 2, ...). A generator that streams into a sink keeps only the frame it
/// is making, so the sink decides what is held: RecordingWriter (below) writes each frame
/// to the file, RecordingCollector keeps them all.
class SceneSink {
public:
    virtual ~SceneSink() = default;
    virtual void begin(const std::string& meta, const std::vector<Object>& initial) = 0;
    virtual void frame(const Frame& frame) = 0;
};

/// Keeps what it is given as a Recording (the in-memory generators are this sink and a stream).
class RecordingCollector final : public SceneSink {
public:
    void begin(const std::string& meta, const std::vector<Object>& initial) override {
        recording.meta = meta;
        recording.initial = initial;
    }
    void frame(const Frame& frame) override { recording.frames.push_back(frame); }
    Recording recording;
};

/// The bounds for a scene streamed frame by frame (SceneSink, RecordingWriter), which holds one
/// frame, not the recording: the object count; one frame in memory (the live objects, its changes
/// and rays) within kMaxRecordingBytes; and the file, at the largest encoding of an object (an
/// oriented box, 45 bytes) and a ray (25), within kMaxStreamedFileBytes; and the rays alone within
/// kMaxRecordingBytes, the in-memory bound.
void check_streamed_scene_size(double objects, double frames, double rays_per_frame, double changes_per_frame,
                               const std::string& where);
/// 16 times the in-memory bound: 10^6 bodies moving in each of 1000 frames fit.
inline constexpr std::uint64_t kMaxStreamedFileBytes = std::uint64_t(64) << 30;
/// Estimated file bytes of a recording of these counts at the largest encodings (version 3).
double streamed_file_bytes(double objects, double frames, double rays_per_frame, double changes_per_frame);

/// Writes a recording to `path` frame by frame, as a generator makes it (a SceneSink): each
/// frame is validated (the reader's checks), encoded and appended to a temporary file beside `path`
/// (hidden, of a name unique in the folder: write_file_atomically's, core/base/output_file.h, so no
/// file of the user's is written over) when frame() is called, so the writer holds no frame and a recording of any
/// length is written in the memory of one frame. finish() appends END and renames the temporary file over `path`;
/// destroyed unfinished (an error, an interrupted generation), the writer deletes the temporary
/// file, and `path` is never touched. The bytes are encode_recording's for the same recording:
/// the header's version is the lowest that holds every frame so far (recording_version), and the
/// first frame that needs a higher one (a shape, a query kind other than `all`) has the file
/// written so far re-encoded at that version, at most twice per recording.
class RecordingWriter final : public SceneSink {
public:
    explicit RecordingWriter(std::string path);
    ~RecordingWriter() override;
    RecordingWriter(const RecordingWriter&) = delete;
    RecordingWriter& operator=(const RecordingWriter&) = delete;

    /// Creates the temporary file and writes the header, META and OBJS. InputError naming the path
    /// for objects the reader would reject or a path that cannot be written.
    void begin(const std::string& meta, const std::vector<Object>& initial) override;
    /// Appends frame number frames() + 1. InputError "<path> (not written): frame N: ..." for a
    /// frame the reader would reject; the writer then takes no more frames.
    void frame(const Frame& frame) override;
    /// Appends END and renames the file into place; the writer takes nothing after it.
    void finish();

    const std::string& path() const { return path_; }
    /// The temporary file the frames go to until finish() (made by begin(); empty before).
    const std::string& temporary_path() const { return tmp_; }
    std::uint32_t frames() const { return frames_; }
    std::uint64_t rays() const { return rays_; }
    std::size_t objects() const { return objects_; }
    std::uint32_t version() const { return version_; }
    /// Bytes in the temporary file: everything given so far, END not yet included.
    std::uint64_t bytes_written() const { return bytes_; }

private:
    /// Appends `bytes` (and flushes when asked); a failed write discards the file and throws.
    void put(const std::string& bytes, bool flush = false);
    void upgrade(std::uint32_t version);
    void discard() noexcept;

    std::string path_, tmp_;
    std::ofstream out_;
    std::unordered_set<Uid> live_;
    std::uint32_t version_ = 1, frames_ = 0;
    std::uint64_t rays_ = 0, bytes_ = 0;
    std::size_t objects_ = 0;
    bool begun_ = false, failed_ = false, finished_ = false;
};

/// Reads a recording section by section: the constructor reads the header, META and OBJS, and
/// next() one frame at a time, each validated as read_recording validates it, so a replay holds
/// one frame instead of the whole file. Errors are read_recording's, word for word.
class RecordingReader {
public:
    explicit RecordingReader(const std::string& path);
    ~RecordingReader();
    RecordingReader(const RecordingReader&) = delete;
    RecordingReader& operator=(const RecordingReader&) = delete;

    std::uint32_t version() const;
    const std::string& meta() const;
    const std::vector<Object>& initial() const;
    /// Frame 0's objects, moved out (initial() is empty after).
    std::vector<Object> take_initial();
    /// Reads the next frame into `frame`; false once the END section is read (and nothing follows it).
    bool next(Frame& frame);

private:
    std::unique_ptr<sections::Reading> state_;
};

}  // namespace rcb
