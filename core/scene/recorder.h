#pragma once
/// Recording an engine's real workload as a `.rcbscene` (format: recording_io.h), one call per
/// change and per ray, so that the structures can be benchmarked on it (`rcbench simulate
/// --scene engine.rcbscene`) and an engine's own structure checked against the ground truth.
///
///     rcb::Recorder rec("level3.rcbscene", R"({"engine": "mine", "level": 3})");
///     for (auto& body : world) rec.insert(body.id, body.box);   // frame 0: the initial objects
///     rec.end_frame();
///     while (running) {                                         // frames 1, 2, …
///         step();  // rec.move(id, box), rec.insert(...), rec.remove(id) as bodies change
///         for (auto& q : queries) rec.ray({q.from, q.to});
///         rec.end_frame();
///     }
///     rec.close();  // writes the file (the destructor does too, if close() was not called)
///
/// Frames. Everything before the first end_frame() is frame 0, the initial objects (the build):
/// inserts add to them, moves change their boxes, removes drop them. A ray before the first
/// end_frame() is an InputError, since frame 0 has no rays: end frame 0 once the world is loaded.
/// Each later end_frame() closes one frame, numbered as in the file (1, 2, …); a frame with no
/// changes and no rays is written too (the engine's frames and the file's stay aligned).
///
/// Replay order. The file keeps, per frame, the changes and then the rays, and the simulator
/// applies all of a frame's changes before casting its rays (thesis §5.2.2): a ray is replayed
/// against the frame's final state, wherever between the changes the engine cast it.
///
/// Coalescing. A frame records, for each uid changed in it, the difference between its state at
/// the frame's start and at end_frame(), so one uid appears at most once per frame as the format
/// requires:
///     insert, then moves          → an insert at the last box
///     moves                       → one move to the last box
///     move(s), then remove        → a remove
///     insert, then remove         → nothing (the structure never sees the object)
///     remove, then insert         → a move to the inserted box
/// Changes are listed in the order their uids were first changed in the frame; rays in call order.
///
/// Errors are rcb::InputError, thrown at the call, naming the file, the frame and the uid or ray
/// ("recorder level3.rcbscene: frame 12: move of unknown uid 7"); the call then has no effect:
///     insert of a live uid, remove or move of a uid that is not live, a box with a NaN or
///     infinite coordinate, one beyond ±kMaxCoordinate (recording_io.h) or with min > max, a ray
///     with such a coordinate, a ray before the first end_frame(), any call after close().
/// Shapes and query kinds. insert() and move() take an object's box, or its exact shape (shape.h:
/// obb, sphere, capsule, triangle), whose box is then the shape's bounds as the format stores it
/// (shape_bounds); a shape with a problem (shape_problem) is refused as a bad box is. ray() takes
/// what the engine asked of the ray (all hits, the closest, any: scene.h, QueryKind), all by default.
/// The file is version 1, 2 or 3 as they need (recording_io.h: the lowest that holds them).
///
/// The constructor refuses meta that is not a JSON object and a path that cannot be written (empty,
/// a directory, a missing or read-only folder), before the engine has run.
///
/// The recording is kept in memory and written by close() atomically (write_recording: a temporary
/// file beside the path, renamed into place), so a crash never leaves a half-written file and an
/// existing file at the path stays as it was until the new one is complete. Not thread-safe: call
/// it from one thread (the engine's main loop).
///
/// This header includes only core/scene/scene.h and core/base/geometry.h (no JSON library, no structures).

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "core/base/geometry.h"
#include "core/scene/scene.h"

namespace rcb {

class Recorder {
public:
    /// `meta_json`: a JSON object describing where the workload came from (engine, level, build),
    /// stored in the file's META section; "generator": "rcb::Recorder" is added unless present.
    explicit Recorder(std::string path, const std::string& meta_json = "{}");
    /// Closes if close() was not called; never throws: a failure to write is printed as one line
    /// on stderr ("rcb::Recorder: <why>; not written").
    ~Recorder();
    Recorder(const Recorder&) = delete;
    Recorder& operator=(const Recorder&) = delete;

    void insert(Uid uid, const Aabb& box);
    void insert(Uid uid, const Shape& shape);
    void remove(Uid uid);
    void move(Uid uid, const Aabb& box);
    void move(Uid uid, const Shape& shape);
    void ray(const Segment& segment, QueryKind kind = QueryKind::all);
    /// Closes the current frame (frame 0 the first time) and starts the next.
    void end_frame();
    /// Ends the current frame if it has any change or ray (else drops it), then writes the file.
    /// The recorder takes no calls after close(), even when writing failed (the exception says
    /// why); a second close() does nothing.
    void close();

    /// The frame the calls go into: 0 until the first end_frame().
    std::uint32_t frame() const;
    /// Objects live now (after this frame's changes so far).
    std::size_t live_count() const;
    bool closed() const;
    const std::string& path() const;

private:
    void add(const Object& o);     // insert's checks after the object's own
    void change(const Object& o);  // move's likewise
    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace rcb
