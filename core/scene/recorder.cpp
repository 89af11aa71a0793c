#include "core/scene/recorder.h"

#include <unistd.h>

#include <cstdio>
#include <exception>
#include <filesystem>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "core/base/json_input.h"
#include "core/scene/recording_io.h"

namespace rcb {

/// The live objects, the frames closed so far, and the current frame's changes as per-uid
/// differences (see "Coalescing" in recorder.h).
struct Recorder::State {
    /// A uid changed in the current frame: whether it was live when the frame started.
    struct Touched {
        Uid uid;
        bool live_at_start;
    };

    std::string path;
    std::string context;  // "recorder <path>", the start of every message
    Recording recording;
    std::unordered_map<Uid, Object> live;  // after the current frame's changes so far
    std::vector<Touched> touched;          // in first-change order
    std::unordered_set<Uid> touched_uids;
    std::vector<Segment> rays;     // the current frame's
    std::vector<QueryKind> kinds;  // one per ray, or empty while every ray is `all`
    std::uint32_t frame = 0;
    bool closed = false;

    std::string where() const { return context + ": frame " + std::to_string(frame); }
    std::string where(Uid uid) const { return where() + ": uid " + std::to_string(uid); }

    void check_open(const char* call) const {
        if (closed) throw InputError(context + ": " + call + "() after close()");
    }
    void check_box(Uid uid, const Aabb& box) const {
        if (std::string problem = box_problem(box); !problem.empty()) throw InputError(where(uid) + ": " + problem);
    }
    /// The object of a shape call: a non-box shape the format accepts, with its bounds as its box.
    Object shaped(Uid uid, const Shape& shape) const {
        if (shape.kind == ShapeKind::box) throw InputError(where(uid) + ": a box-kind shape (pass the box itself)");
        if (std::string problem = shape_problem(shape, kMaxCoordinate); !problem.empty())
            throw InputError(where(uid) + ": " + problem);
        return shaped_object(uid, shape);
    }
    /// " (removed earlier in this frame)" when that is why `uid` is not live, for messages.
    std::string why_not_live(Uid uid) const {
        return touched_uids.count(uid) ? " (removed earlier in this frame)" : " (not live)";
    }
    /// Notes that `uid` changes in this frame (with its liveness before its first change).
    void touch(Uid uid) {
        if (touched_uids.insert(uid).second) touched.push_back({uid, live.count(uid) != 0});
    }

    /// The current frame's changes from the per-uid differences; clears them.
    Frame take_frame() {
        Frame f;
        for (const Touched& t : touched) {
            auto it = live.find(t.uid);
            const bool live_now = it != live.end();
            if (t.live_at_start && !live_now)
                f.removes.push_back(t.uid);
            else if (!t.live_at_start && live_now)
                f.inserts.push_back(it->second);
            else if (live_now)
                f.moves.push_back(it->second);
        }
        f.rays = std::move(rays);
        f.kinds = std::move(kinds);
        rays.clear();
        kinds.clear();
        touched.clear();
        touched_uids.clear();
        return f;
    }

    void end_frame() {
        Frame f = take_frame();
        if (frame == 0)
            recording.initial = std::move(f.inserts);  // nothing was live at the start
        else
            recording.frames.push_back(std::move(f));
        ++frame;
    }
};

namespace {

/// Refuses, before the engine runs, a path that write_recording could not write.
void check_path(const std::string& path, const std::string& context) {
    namespace fs = std::filesystem;
    if (path.empty()) throw InputError("recorder: empty output path");
    std::error_code ec;
    if (fs::is_directory(path, ec)) throw InputError(context + ": is a directory, not a file to write");
    fs::path folder = fs::path(path).parent_path();
    if (folder.empty()) folder = ".";
    if (!fs::is_directory(folder, ec)) throw InputError(context + ": folder " + folder.string() + " does not exist");
    // The temporary file is created in that folder and renamed over the path.
    if (::access(folder.c_str(), W_OK | X_OK) != 0)
        throw InputError(context + ": folder " + folder.string() + " is not writable");
}

}  // namespace

Recorder::Recorder(std::string path, const std::string& meta_json) : state_(std::make_unique<State>()) {
    State& s = *state_;
    s.context = "recorder " + path;
    check_path(path, s.context);
    nlohmann::json meta = parse_json_document(meta_json, s.context + ": meta");
    if (!meta.is_object()) throw InputError(s.context + ": meta must be a JSON object, got " + json_excerpt(meta));
    if (!meta.contains("generator")) meta["generator"] = "rcb::Recorder";
    s.recording.meta = meta.dump();
    s.path = std::move(path);
}

Recorder::~Recorder() {
    if (!state_ || state_->closed) return;
    try {
        close();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "rcb::Recorder: %s; not written\n", e.what());
    } catch (...) {
        std::fprintf(stderr, "rcb::Recorder: %s: unknown error; not written\n", state_->path.c_str());
    }
}

void Recorder::insert(Uid uid, const Aabb& box) {
    state_->check_open("insert");
    state_->check_box(uid, box);
    add(Object{uid, box});
}

void Recorder::insert(Uid uid, const Shape& shape) {
    state_->check_open("insert");
    add(state_->shaped(uid, shape));
}

void Recorder::add(const Object& o) {
    State& s = *state_;
    if (s.live.count(o.uid))
        throw InputError(s.where() + ": insert of uid " + std::to_string(o.uid) + ", which is already live");
    s.touch(o.uid);
    s.live.emplace(o.uid, o);
}

void Recorder::remove(Uid uid) {
    State& s = *state_;
    s.check_open("remove");
    auto it = s.live.find(uid);
    if (it == s.live.end())
        throw InputError(s.where() + ": remove of unknown uid " + std::to_string(uid) + s.why_not_live(uid));
    s.touch(uid);
    s.live.erase(it);
}

void Recorder::move(Uid uid, const Aabb& box) {
    state_->check_open("move");
    state_->check_box(uid, box);
    change(Object{uid, box});
}

void Recorder::move(Uid uid, const Shape& shape) {
    state_->check_open("move");
    change(state_->shaped(uid, shape));
}

void Recorder::change(const Object& o) {
    State& s = *state_;
    auto it = s.live.find(o.uid);
    if (it == s.live.end())
        throw InputError(s.where() + ": move of unknown uid " + std::to_string(o.uid) + s.why_not_live(o.uid));
    s.touch(o.uid);
    it->second = o;
}

void Recorder::ray(const Segment& segment, QueryKind kind) {
    State& s = *state_;
    s.check_open("ray");
    auto label = [&] { return s.where() + ": ray " + std::to_string(s.rays.size()); };
    if (s.frame == 0)
        throw InputError(label() +
                         " cast before the first end_frame() (frame 0 is the initial objects only: call end_frame() "
                         "once the world is loaded)");
    if (std::string problem = segment_problem(segment); !problem.empty()) throw InputError(label() + ": " + problem);
    if (int(kind) >= kQueryKinds) throw InputError(label() + ": unknown query kind " + std::to_string(int(kind)));
    // The kinds stay empty while every ray asks for all hits (Frame::kinds), so such a recording
    // keeps its older format version.
    if (kind != QueryKind::all || !s.kinds.empty()) {
        s.kinds.resize(s.rays.size(), QueryKind::all);
        s.kinds.push_back(kind);
    }
    s.rays.push_back(segment);
}

void Recorder::end_frame() {
    state_->check_open("end_frame");
    state_->end_frame();
}

void Recorder::close() {
    State& s = *state_;
    if (s.closed) return;
    s.closed = true;
    if (s.frame == 0 || !s.touched.empty() || !s.rays.empty()) s.end_frame();
    write_recording(s.recording, s.path);
    s.recording = Recording{};  // the file holds it now: free the memory of a long recording
}

std::uint32_t Recorder::frame() const { return state_->frame; }
std::size_t Recorder::live_count() const { return state_->live.size(); }
bool Recorder::closed() const { return state_->closed; }
const std::string& Recorder::path() const { return state_->path; }

}  // namespace rcb
