#include "core/scene/recording_stream.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "core/base/error.h"
#include "core/base/output_file.h"
#include "core/scene/recording_sections.h"

namespace rcb {

double streamed_file_bytes(double objects, double frames, double rays_per_frame, double changes_per_frame) {
    constexpr double object_bytes = 4 + 1 + 10 * 4, ray_bytes = 6 * 4 + 1, frame_bytes = 16 + 5 * 4;
    return objects * object_bytes +
           frames * (frame_bytes + changes_per_frame * object_bytes + rays_per_frame * ray_bytes);
}

void check_streamed_scene_size(double objects, double frames, double rays_per_frame, double changes_per_frame,
                               const std::string& where) {
    check_object_count(objects, where);
    char text[200];
    const double frame = recording_bytes(objects, 1, rays_per_frame, changes_per_frame);
    if (!(frame <= double(kMaxRecordingBytes))) {
        std::snprintf(
            text, sizeof text,
            "one frame would take %.3g GB in memory (%.0f objects, %.0f rays), more than the limit of %.3g GB",
            frame / 1e9, objects, rays_per_frame, double(kMaxRecordingBytes) / 1e9);
        throw InputError(where + ": " + text + "; use fewer rays or objects");
    }
    const double file = streamed_file_bytes(objects, frames, rays_per_frame, changes_per_frame);
    if (!(file <= double(kMaxStreamedFileBytes))) {
        std::snprintf(text, sizeof text,
                      "the recording could take %.3g GB on disk (%.0f objects, %.0f frames of %.0f rays), more than "
                      "the limit of %.3g GB",
                      file / 1e9, objects, frames, rays_per_frame, double(kMaxStreamedFileBytes) / 1e9);
        throw InputError(where + ": " + text + "; use fewer frames, rays or objects");
    }
    // Streaming lifts the bound for moving objects, not for rays: a recording's rays stay within
    // the in-memory bound, as before, so that an absurd --rays is refused instead of generated.
    const double rays = streamed_file_bytes(0, frames, rays_per_frame, 0);
    if (!(rays <= double(kMaxRecordingBytes))) {
        std::snprintf(text, sizeof text,
                      "the recording's rays could take %.3g GB (%.0f frames of %.0f rays), more than the limit of "
                      "%.3g GB",
                      rays / 1e9, frames, rays_per_frame, double(kMaxRecordingBytes) / 1e9);
        throw InputError(where + ": " + text + "; use fewer rays or frames");
    }
}

RecordingReader::RecordingReader(const std::string& path) : state_(sections::open_reading(path, false)) {
    state_->read_prologue();
}

RecordingReader::~RecordingReader() = default;

std::uint32_t RecordingReader::version() const { return state_->version; }
const std::string& RecordingReader::meta() const { return state_->meta; }
const std::vector<Object>& RecordingReader::initial() const { return state_->initial; }
std::vector<Object> RecordingReader::take_initial() { return std::move(state_->initial); }

bool RecordingReader::next(Frame& frame) {
    while (state_->expect == sections::Reading::Expect::frames)
        if (state_->section(&frame)) return true;
    return false;
}

RecordingWriter::RecordingWriter(std::string path) : path_(std::move(path)) {}

RecordingWriter::~RecordingWriter() {
    if (!finished_) discard();
}

void RecordingWriter::discard() noexcept {
    if (out_.is_open()) out_.close();
    std::error_code ec;
    if (begun_) std::filesystem::remove(tmp_, ec);
    failed_ = true;
}

void RecordingWriter::put(const std::string& bytes, bool flush) {
    out_.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (flush) out_.flush();
    if (!out_) {
        const std::string why = std::strerror(errno);
        discard();
        throw std::runtime_error(path_ + ": write failed (" + why + "); nothing written");
    }
    bytes_ += bytes.size();
}

void RecordingWriter::begin(const std::string& meta, const std::vector<Object>& initial) {
    if (begun_ || failed_ || finished_) throw InputError(path_ + ": the recording was begun already");
    live_ = sections::refuse_invalid_initial(initial, path_ + " (not written)");
    sections::refuse_missing_folder(path_);
    tmp_ = create_temporary_file_for(path_);  // InputError naming the path when it cannot be written
    begun_ = true;
    out_.open(tmp_, std::ios::binary | std::ios::trunc);
    if (!out_) {
        discard();
        throw InputError(path_ + ": cannot open for writing");
    }
    version_ = sections::objects_version(initial);
    objects_ = initial.size();
    put(sections::header_bytes(version_) + sections::meta_section(meta) + sections::objects_section(initial, version_),
        true);
}

void RecordingWriter::frame(const Frame& f) {
    if (!begun_ || failed_ || finished_)
        throw InputError(path_ + ": a frame given " + (begun_ ? "after an error or finish()" : "before begin()"));
    try {
        sections::refuse_invalid_frame(f, live_, sections::frame_context(path_ + " (not written)", frames_ + 1));
    } catch (...) {
        discard();
        throw;
    }
    if (const std::uint32_t needed = sections::frame_version(f); needed > version_) upgrade(needed);
    // Flushed per frame: the file holds every whole frame given so far, and the writer keeps none.
    put(sections::frame_section(f, frames_ + 1, version_), true);
    ++frames_;
    rays_ += f.rays.size();
}

/// Re-encodes the temporary file at `version`: read back section by section (one frame at a
/// time) into a second temporary file, which replaces it.
void RecordingWriter::upgrade(std::uint32_t version) {
    out_.close();
    std::string next;
    try {
        next = create_temporary_file_for(path_);
        const auto reading = sections::open_reading(tmp_, true);
        sections::Reading& in = *reading;
        in.read_prologue();
        std::ofstream out(next, std::ios::binary | std::ios::trunc);
        std::string bytes = sections::header_bytes(version) + sections::meta_section(in.meta) +
                            sections::objects_section(in.initial, version);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        std::uint64_t total = bytes.size();
        for (Frame f; in.section(&f);) {
            bytes = sections::frame_section(f, in.frames_seen, version);
            out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
            total += bytes.size();
        }
        out.flush();
        if (!out) throw std::runtime_error(std::strerror(errno));
        out.close();
        std::filesystem::rename(next, tmp_);
        bytes_ = total;
    } catch (const std::exception& e) {
        std::error_code ec;
        if (!next.empty()) std::filesystem::remove(next, ec);
        discard();
        throw std::runtime_error(path_ + ": cannot rewrite the recording at version " + std::to_string(version) + " (" +
                                 e.what() + "); nothing written");
    }
    version_ = version;
    out_.open(tmp_, std::ios::binary | std::ios::app);
    if (!out_) {
        discard();
        throw std::runtime_error(path_ + ": cannot reopen the temporary file; nothing written");
    }
}

void RecordingWriter::finish() {
    if (!begun_ || failed_ || finished_)
        throw InputError(path_ + ": finish() " + (begun_ ? "after an error or a finish()" : "before begin()"));
    put(sections::end_section());
    out_.flush();
    out_.close();
    if (!out_) {
        discard();
        throw std::runtime_error(path_ + ": write failed; nothing written");
    }
    try {
        replace_with_temporary_file(tmp_, path_);
    } catch (...) {
        discard();
        throw;
    }
    finished_ = true;
}

}  // namespace rcb
