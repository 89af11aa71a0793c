// The recorder: what an engine records per frame reads back as the expected recording, a uid changed
// several times in a frame is coalesced into one change, and every misuse is an InputError naming
// the file, the frame and the uid or ray, without spoiling the recording.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>

#include "core/base/error.h"
#include "core/scene/recorder.h"
#include "core/scene/recording_io.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

/// A fresh folder per test, removed at the end.
class RecorderTest : public ::testing::Test {
protected:
    std::string path(const std::string& name = "scene.rcbscene") const { return dir_.file(name); }

    test::TempDir dir_{"recorder"};  // rcb_recorder_<pid>_<test>, removed after the test
};

Aabb box(float x, float y = 0, float z = 0, float size = 1) { return {{x, y, z}, {x + size, y + size, z + size}}; }
Segment seg(float x0, float x1) { return {{x0, 0.5f, 0.5f}, {x1, 0.5f, 0.5f}}; }

const auto error_of = test::input_error_of;

std::string contents(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

TEST_F(RecorderTest, RecordedFramesReadBackAsTheExpectedRecording) {
    Recording expected;
    expected.meta = R"({"engine":"toy","generator":"rcb::Recorder","level":3})";
    expected.initial = {{10, box(0)}, {11, box(5)}, {12, box(10)}};
    expected.frames.resize(3);
    expected.frames[0].moves = {{11, box(6)}};
    expected.frames[0].rays = {seg(-1, 20), seg(4, 4.5f)};
    expected.frames[1].inserts = {{13, box(20)}};
    expected.frames[1].removes = {10};
    expected.frames[1].rays = {seg(0, 30)};
    // frame 3: nothing changes and no ray is cast; it is written all the same.

    {
        Recorder rec(path(), R"({"engine": "toy", "level": 3})");
        for (const Object& o : expected.initial) rec.insert(o.uid, o.box);
        EXPECT_EQ(rec.frame(), 0u);
        rec.end_frame();
        EXPECT_EQ(rec.frame(), 1u);
        rec.move(11, box(6));
        rec.ray(seg(-1, 20));
        rec.ray(seg(4, 4.5f));
        rec.end_frame();
        rec.insert(13, box(20));
        rec.remove(10);
        rec.ray(seg(0, 30));
        rec.end_frame();
        EXPECT_EQ(rec.live_count(), 3u);
        rec.end_frame();
        EXPECT_FALSE(fs::exists(path())) << "written before close()";
        rec.close();
        EXPECT_TRUE(rec.closed());
    }
    EXPECT_EQ(read_recording(path()), expected);
    // Nothing else is left in the folder: no temporary file.
    EXPECT_EQ(std::distance(fs::directory_iterator(dir_.path()), fs::directory_iterator{}), 1);
}

/// A generated scene (every kind of change, all ray modes), replayed call by call through the
/// recorder, reads back as itself: the recorder writes what the engine did, in its order.
TEST_F(RecorderTest, ReplayingAGeneratedSceneReproducesIt) {
    Recording r = test::generated_scene("irregular", 800, 6, 21, 0.2);
    r.meta = R"({"generator":"test"})";
    {
        Recorder rec(path(), r.meta);
        for (const Object& o : r.initial) rec.insert(o.uid, o.box);
        rec.end_frame();
        for (const Frame& f : r.frames) {
            for (Uid uid : f.removes) rec.remove(uid);
            for (const Object& o : f.inserts) rec.insert(o.uid, o.box);
            for (const Object& o : f.moves) rec.move(o.uid, o.box);
            for (const Segment& s : f.rays) rec.ray(s);
            rec.end_frame();
        }
    }  // the destructor closes
    EXPECT_EQ(read_recording(path()), r);
    // And it replays with every hit matching the ground truth.
    test::expect_matches_ground_truth(read_recording(path()), "bf", nlohmann::json::object(), "recorded");
}

TEST_F(RecorderTest, ChangesToOneUidInAFrameCoalesce) {
    Recorder rec(path());
    for (Uid uid = 1; uid <= 6; ++uid) rec.insert(uid, box(float(uid)));
    rec.end_frame();
    rec.insert(20, box(0));  // insert, then moves: an insert at the last box
    rec.move(20, box(1));
    rec.move(20, box(2));
    rec.move(1, box(7));  // moves: one move to the last box
    rec.move(1, box(8));
    rec.move(2, box(9));  // move, then remove: a remove
    rec.remove(2);
    rec.insert(21, box(3));  // insert, then remove: nothing
    rec.remove(21);
    rec.remove(3);  // remove, then insert: a move to the inserted box
    rec.insert(3, box(30));
    rec.remove(4);  // remove, insert, remove: a remove
    rec.insert(4, box(40));
    rec.remove(4);
    rec.move(5, box(50));  // remove after a re-insert after a move...: still one change
    rec.remove(5);
    rec.insert(5, box(5));
    rec.end_frame();
    rec.close();

    Frame expected;
    expected.inserts = {{20, box(2)}};
    expected.moves = {{1, box(8)}, {3, box(30)}, {5, box(5)}};  // in the order the uids were first changed
    expected.removes = {2, 4};
    const Recording r = read_recording(path());
    ASSERT_EQ(r.frames.size(), 1u);
    EXPECT_EQ(r.frames[0], expected);
}

TEST_F(RecorderTest, FrameZeroIsTheStateAtTheFirstEndFrame) {
    Recorder rec(path());
    rec.insert(1, box(0));
    rec.insert(2, box(1));
    rec.insert(3, box(2));
    rec.move(2, box(9));
    rec.remove(1);
    rec.insert(4, box(4));
    rec.remove(3);
    rec.insert(3, box(3));  // removed and inserted again in frame 0: keeps its first place
    rec.close();            // close() ends frame 0 and writes no frame after it
    const Recording r = read_recording(path());
    EXPECT_EQ(r.initial, (std::vector<Object>{{2, box(9)}, {3, box(3)}, {4, box(4)}}));
    EXPECT_TRUE(r.frames.empty());
}

TEST_F(RecorderTest, CloseEndsAnOpenFrameOnlyIfItHasSomething) {
    {
        Recorder rec(path("a.rcbscene"));
        rec.insert(1, box(0));
        rec.end_frame();
        rec.ray(seg(-1, 2));
        rec.close();  // the open frame has a ray: written
        rec.close();  // a second close() does nothing
    }
    EXPECT_EQ(read_recording(path("a.rcbscene")).frames.size(), 1u);
    {
        Recorder rec(path("b.rcbscene"));
        rec.insert(1, box(0));
        rec.end_frame();
        rec.move(1, box(1));
        rec.end_frame();
        rec.close();  // the open frame is empty: dropped
    }
    EXPECT_EQ(read_recording(path("b.rcbscene")).frames.size(), 1u);
}

TEST_F(RecorderTest, MisuseIsAnErrorNamingFileFrameAndUid) {
    Recorder rec(path());
    rec.insert(7, box(0));
    rec.insert(8, box(1));
    const std::string at0 = "recorder " + path() + ": frame 0: ";
    EXPECT_EQ(error_of([&] { rec.insert(7, box(2)); }), at0 + "insert of uid 7, which is already live");
    EXPECT_EQ(
        error_of([&] { rec.ray(seg(0, 1)); }),
        at0 +
            "ray 0 cast before the first end_frame() (frame 0 is the initial objects only: call end_frame() once the "
            "world is loaded)");
    rec.end_frame();
    rec.end_frame();
    const std::string at2 = "recorder " + path() + ": frame 2: ";
    EXPECT_EQ(error_of([&] { rec.insert(8, box(2)); }), at2 + "insert of uid 8, which is already live");
    EXPECT_EQ(error_of([&] { rec.remove(9); }), at2 + "remove of unknown uid 9 (not live)");
    EXPECT_EQ(error_of([&] { rec.move(9, box(0)); }), at2 + "move of unknown uid 9 (not live)");
    rec.remove(8);
    EXPECT_EQ(error_of([&] { rec.remove(8); }), at2 + "remove of unknown uid 8 (removed earlier in this frame)");
    EXPECT_EQ(error_of([&] { rec.move(8, box(3)); }), at2 + "move of unknown uid 8 (removed earlier in this frame)");
    const float nan = std::numeric_limits<float>::quiet_NaN();
    EXPECT_EQ(error_of([&] { rec.insert(9, {{0, 0, 0}, {nan, 1, 1}}); }), at2 + "uid 9: non-finite coordinate");
    EXPECT_EQ(error_of([&] { rec.move(7, {{0, 2, 0}, {1, 1, 1}}); }), at2 + "uid 7: min > max on axis y");
    EXPECT_NE(error_of([&] { rec.move(7, box(1e16f)); }).find(at2 + "uid 7: coordinate 1e+16 beyond"),
              std::string::npos);
    rec.ray(seg(0, 1));
    EXPECT_EQ(error_of([&] {
                  rec.ray({{0, 0, 0}, {0, std::numeric_limits<float>::infinity(), 0}});
              }),
              at2 + "ray 1: non-finite coordinate");
    rec.end_frame();
    rec.close();
    EXPECT_EQ(error_of([&] { rec.insert(1, box(0)); }), "recorder " + path() + ": insert() after close()");
    EXPECT_EQ(error_of([&] { rec.ray(seg(0, 1)); }), "recorder " + path() + ": ray() after close()");
    EXPECT_EQ(error_of([&] { rec.end_frame(); }), "recorder " + path() + ": end_frame() after close()");

    // Every refused call left the recording as it was.
    Recording expected;
    expected.meta = R"({"generator":"rcb::Recorder"})";
    expected.initial = {{7, box(0)}, {8, box(1)}};
    expected.frames.resize(2);
    expected.frames[1].removes = {8};
    expected.frames[1].rays = {seg(0, 1)};
    EXPECT_EQ(read_recording(path()), expected);
}

TEST_F(RecorderTest, BadPathOrMetaIsRefusedBeforeRecording) {
    EXPECT_EQ(error_of([&] { Recorder rec(""); }), "recorder: empty output path");
    EXPECT_EQ(error_of([&] { Recorder rec(dir_.path().string()); }),
              "recorder " + dir_.path().string() + ": is a directory, not a file to write");
    const std::string missing = (dir_.path() / "no" / "x.rcbscene").string();
    EXPECT_EQ(error_of([&] { Recorder rec(missing); }),
              "recorder " + missing + ": folder " + (dir_.path() / "no").string() + " does not exist");
    EXPECT_EQ(error_of([&] { Recorder rec(path(), "[1, 2]"); }),
              "recorder " + path() + ": meta must be a JSON object, got [1,2]");
    EXPECT_NE(error_of([&] { Recorder rec(path(), "{\"engine\": "); }).find("recorder " + path() + ": meta"),
              std::string::npos);
    EXPECT_FALSE(fs::exists(path()));
}

TEST_F(RecorderTest, AnExistingFileStaysUntilTheNewOneIsComplete) {
    std::ofstream(path()) << "previous";
    {
        Recorder rec(path());
        rec.insert(1, box(0));
        rec.end_frame();
        EXPECT_EQ(contents(path()), "previous");
    }
    EXPECT_EQ(read_recording(path()).initial.size(), 1u);
}

/// The destructor writes when close() was not called, and a failure there is reported on stderr,
/// never thrown (the destructor may run while an exception unwinds the engine).
TEST_F(RecorderTest, DestructorNeverThrows) {
    const fs::path sub = dir_.path() / "sub";
    fs::create_directories(sub);
    const std::string p = (sub / "x.rcbscene").string();
    ::testing::internal::CaptureStderr();
    EXPECT_NO_THROW({
        Recorder rec(p);
        rec.insert(1, box(0));
        fs::remove_all(sub);  // the folder disappears while the engine runs
    });
    const std::string err = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(err.rfind("rcb::Recorder: ", 0), 0u) << err;
    EXPECT_NE(err.find("x.rcbscene"), std::string::npos) << err;
    EXPECT_NE(err.find("; not written\n"), std::string::npos) << err;
    EXPECT_FALSE(fs::exists(p));
}

TEST_F(RecorderTest, ShapesAndQueryKindsReadBack) {
    const Shape ball = Shape::sphere({1, 2, 3}, 0.5f), moved = Shape::sphere({1, 1, 3}, 0.5f);
    const Shape crate = Shape::obb({5, 0, 0}, {1, 0.5f, 0.25f}, {0.9f, 0, 0.1f, 0});
    {
        Recorder rec(path());
        rec.insert(1, ball);
        rec.insert(2, box(10));
        rec.end_frame();
        rec.move(1, moved);
        rec.insert(3, crate);
        rec.ray(seg(-1, 20));  // all hits: the kinds start only with the first other kind
        rec.ray(seg(-1, 20), QueryKind::closest);
        rec.ray(seg(-1, 20), QueryKind::any);
        rec.end_frame();
        rec.ray(seg(0, 1));  // a frame of all-hits rays keeps no kinds
        rec.close();
    }
    const Recording r = read_recording(path());
    ASSERT_EQ(r.initial.size(), 2u);
    EXPECT_EQ(r.initial[0], shaped_object(1, ball));
    EXPECT_EQ(r.initial[1], (Object{2, box(10)}));
    ASSERT_EQ(r.frames.size(), 2u);
    EXPECT_EQ(r.frames[0].moves, std::vector<Object>{shaped_object(1, moved)});
    ASSERT_EQ(r.frames[0].inserts.size(), 1u);
    EXPECT_EQ(r.frames[0].inserts[0].shape, shaped_object(3, crate).shape);  // the rotation normalised
    EXPECT_EQ(r.frames[0].kinds, (std::vector<QueryKind>{QueryKind::all, QueryKind::closest, QueryKind::any}));
    EXPECT_TRUE(r.frames[1].kinds.empty());

    Recorder rec(path("bad.rcbscene"));
    test::expect_input_error(
        [&] {
            rec.insert(4, Shape::sphere({0, 0, 0}, -1));
        },
        "frame 0: uid 4: sphere has a negative radius");
    test::expect_input_error([&] { rec.insert(4, Shape{}); }, "frame 0: uid 4: a box-kind shape");
    test::expect_input_error([&] { rec.move(4, ball); }, "move of unknown uid 4");
    EXPECT_EQ(rec.live_count(), 0u);
    rec.close();
}

}  // namespace
}  // namespace rcb
