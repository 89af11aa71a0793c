// Streamed recordings (core/scene/recording_stream.h): the writer appends each frame as it is given
// and writes write_recording's bytes, raising the version when a frame needs it; the reader reads a
// frame at a time with the whole-file reader's checks; `scene gen` streams, refuses what it cannot
// write in one line, and never leaves a partial file under the requested name.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/generate/physics.h"
#include "core/scene/generate/stream.h"
#include "core/scene/recording_io.h"
#include "core/scene/recording_stream.h"
#include "tests/subprocess.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

std::string file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

/// The names in `dir`, sorted.
std::vector<std::string> names_in(const std::filesystem::path& dir) {
    std::vector<std::string> names;
    for (const fs::directory_entry& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

/// A generated scene of `preset` with `frames` frames.
Recording preset_scene(const char* preset, std::uint32_t frames) {
    SceneSettings s = preset_settings(preset);
    s.frames = frames;
    return generate_scene(s);
}

/// Bytes of the END section, which encode_recording ends with and the writer adds in finish().
constexpr std::size_t kEndBytes = 16;

/// Writes `r` through a RecordingWriter; after every frame, the temporary file holds exactly the
/// encoding of the recording so far (without END): the writer keeps no frame back.
void write_streamed(const Recording& r, const std::string& path) {
    RecordingWriter w(path);
    w.begin(r.meta, r.initial);
    Recording prefix{r.meta, r.initial, {}};
    for (const Frame& f : r.frames) {
        w.frame(f);
        prefix.frames.push_back(f);
        ASSERT_EQ(fs::file_size(w.temporary_path()), w.bytes_written());
        ASSERT_EQ(w.bytes_written() + kEndBytes, encode_recording(prefix).size()) << "frame " << prefix.frames.size();
        ASSERT_EQ(w.version(), recording_version(prefix));
    }
    EXPECT_FALSE(fs::exists(path));  // nothing under the name before finish()
    w.finish();
    EXPECT_FALSE(fs::exists(w.temporary_path()));
}

TEST(RecordingStream, TheWriterWritesWhatWriteRecordingWrites) {
    const test::TempDir dir("stream");
    SceneSettings s = preset_settings("irreg-s");
    s.frames = 6;
    s.rays.per_frame = 20;
    const Recording boxes = generate_scene(s);
    // Version 2 from frame 0 on (every object shaped).
    const Recording shaped = test::with_shapes(boxes, 9);
    // Shapes first appearing in frame 4: the writer starts at version 1 and rewrites at 2.
    Recording late_shapes = boxes;
    for (std::size_t i = 3; i < late_shapes.frames.size(); ++i) late_shapes.frames[i] = shaped.frames[i];
    // A query kind other than `all` from frame 5: version 1, then 3.
    Recording late_kinds = boxes;
    late_kinds.frames[4].kinds.assign(late_kinds.frames[4].rays.size(), QueryKind::closest);
    for (const auto& [name, r] : {std::pair<const char*, const Recording&>{"boxes", boxes},
                                  {"shaped", shaped},
                                  {"late shapes", late_shapes},
                                  {"late kinds", late_kinds}}) {
        SCOPED_TRACE(name);
        const std::string path = dir.file(std::string(name) + ".rcbscene");
        write_streamed(r, path);
        EXPECT_EQ(file_bytes(path), encode_recording(r));
        EXPECT_EQ(read_recording(path), r);
    }
    EXPECT_EQ(recording_version(boxes), 1u);
    EXPECT_EQ(recording_version(shaped), 2u);
    EXPECT_EQ(recording_version(late_shapes), 2u);
    EXPECT_EQ(recording_version(late_kinds), 3u);
}

TEST(RecordingStream, AFrameThatNeedsAHigherVersionRewritesTheFileSoFar) {
    const test::TempDir dir("stream");
    // Frames 1-2 boxes only, frame 3 moves an object into a sphere, frame 4 asks closest hits:
    // the writer goes 1 -> 2 -> 3 and the file equals the single-pass encoding.
    Recording r;
    r.meta = R"({"test": "upgrade"})";
    for (Uid u = 0; u < 4; ++u) r.initial.push_back({u, Aabb{{float(u), 0, 0}, {float(u) + 1, 1, 1}}});
    Frame f1, f2, f3, f4;
    f1.moves.push_back({1, Aabb{{1, 1, 0}, {2, 2, 1}}});
    f1.rays.push_back({{-1, 0.5f, 0.5f}, {9, 0.5f, 0.5f}});
    f2.removes.push_back(2);
    f3.moves.push_back(shaped_object(3, Shape::sphere({3.5f, 0.5f, 0.5f}, 0.5f)));
    f3.inserts.push_back({7, Aabb{{0, 5, 0}, {1, 6, 1}}});
    f4.rays.push_back({{0, 0, 0}, {1, 1, 1}});
    f4.rays.push_back({{0, 1, 0}, {1, 1, 1}});
    f4.kinds = {QueryKind::any, QueryKind::all};
    r.frames = {f1, f2, f3, f4};
    const std::string path = dir.file("up.rcbscene");
    write_streamed(r, path);
    EXPECT_EQ(file_bytes(path), encode_recording(r));
    EXPECT_EQ(read_recording(path), r);
}

TEST(RecordingStream, StreamedGenerationGivesTheSameBytesAsTheWholeRecording) {
    const test::TempDir dir("stream");
    for (const std::string generator : {"brownian", "pile", "gravity"}) {
        SCOPED_TRACE(generator);
        SceneSettings s;
        s.generator = generator;
        s.objects = 300;
        s.frames = 12;
        s.seed = 5;
        s.rays.per_frame = 30;
        const std::string path = dir.file(generator + ".rcbscene");
        RecordingWriter w(path);
        stream_scene(s, w);
        w.finish();
        EXPECT_EQ(file_bytes(path), encode_recording(generate_scene(s)));
    }
    SceneSettings plain = preset_settings("uni-s");
    plain.frames = 5;
    RecordingWriter w(dir.file("uni.rcbscene"));
    stream_scene(plain, w);
    w.finish();
    EXPECT_EQ(file_bytes(dir.file("uni.rcbscene")), encode_recording(generate_scene(plain)));
}

TEST(RecordingStream, APhysicsRunRecordsEachFrameAsGenerationDoes) {
    SceneSettings s;
    s.generator = "freefall";
    s.objects = 200;
    s.frames = 8;
    s.rays.per_frame = 10;
    const Recording whole = generate_physics_scene(s);
    PhysicsRun run(s);
    EXPECT_EQ(run.initial(), whole.initial);
    EXPECT_EQ(run.meta(), whole.meta);
    for (std::uint32_t f = 1; f <= s.frames; ++f) {
        run.step();
        EXPECT_EQ(run.frame(), f);
        EXPECT_EQ(run.record(), whole.frames[f - 1]) << "frame " << f;
    }
    EXPECT_GT(run.awake_bodies(), 0u);
}

TEST(RecordingStream, TheReaderReadsOneFrameAtATimeWithTheSameChecks) {
    const test::TempDir dir("stream");
    const Recording r = preset_scene("irreg-s", 4);
    const std::string path = dir.file("r.rcbscene");
    write_recording(r, path);
    RecordingReader reader(path);
    EXPECT_EQ(reader.meta(), r.meta);
    EXPECT_EQ(reader.initial(), r.initial);
    Frame f;
    for (const Frame& expected : r.frames) {
        ASSERT_TRUE(reader.next(f));
        EXPECT_EQ(f, expected);
    }
    EXPECT_FALSE(reader.next(f));
    // A file cut inside frame 3 reads frames 1 and 2, then fails naming frame 3.
    const std::string bytes = encode_recording(r);
    const std::size_t cut =
        encode_recording(Recording{r.meta, r.initial, {r.frames[0], r.frames[1]}}).size() - kEndBytes + 30;
    std::ofstream(dir.file("cut.rcbscene"), std::ios::binary) << bytes.substr(0, cut);
    RecordingReader cut_reader(dir.file("cut.rcbscene"));
    ASSERT_TRUE(cut_reader.next(f));
    ASSERT_TRUE(cut_reader.next(f));
    test::expect_input_error([&] { cut_reader.next(f); }, "cut.rcbscene: frame 3: truncated");
}

TEST(RecordingStream, AnUnfinishedOrRefusedWriterLeavesNoFile) {
    const test::TempDir dir("stream");
    const Recording r = preset_scene("uni-s", 3);
    const std::string path = dir.file("keep.rcbscene");
    std::ofstream(path) << "an existing file";
    {
        RecordingWriter w(path);
        w.begin(r.meta, r.initial);
        w.frame(r.frames[0]);
        EXPECT_TRUE(fs::exists(w.temporary_path()));
    }  // destroyed before finish(): an interrupted generation
    EXPECT_EQ(file_bytes(path), "an existing file");
    EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"keep.rcbscene"});  // no temporary file left
    // A frame the reader would reject: refused naming the frame, nothing left behind.
    RecordingWriter w(path);
    w.begin(r.meta, r.initial);
    w.frame(r.frames[0]);
    Frame bad;
    bad.removes.push_back(999999);
    test::expect_input_error([&] { w.frame(bad); },
                             "keep.rcbscene (not written): frame 2: remove of unknown uid 999999");
    EXPECT_FALSE(fs::exists(w.temporary_path()));
    test::expect_input_error([&] { w.finish(); }, "after an error");
    EXPECT_EQ(file_bytes(path), "an existing file");
}

TEST(RecordingStream, TheTemporaryFileNeverTakesAUsersFile) {
    // The writer's temporary file is hidden and of a name unique in the folder, made when the
    // recording begins: a file of the user's named "<path>.tmp" is left as it was, through a
    // version upgrade (a second temporary file), a finished recording and an abandoned one.
    const test::TempDir dir("stream");
    const std::string path = dir.file("r.rcbscene");
    std::ofstream(path + ".tmp") << "the user's notes";
    Recording r = preset_scene("uni-s", 3);
    r.frames[1].kinds.assign(r.frames[1].rays.size(), QueryKind::closest);  // version 1, then 3
    {
        RecordingWriter w(path);
        EXPECT_EQ(w.temporary_path(), "");
        w.begin(r.meta, r.initial);
        const fs::path tmp = w.temporary_path();
        EXPECT_EQ(tmp.parent_path(), dir.path());
        EXPECT_EQ(tmp.filename().string().rfind(".r.rcbscene.", 0), 0u) << tmp;
        w.frame(r.frames[0]);
        w.frame(r.frames[1]);
        EXPECT_EQ(w.version(), 3u);
        EXPECT_EQ(names_in(dir.path()), (std::vector<std::string>{tmp.filename().string(), "r.rcbscene.tmp"}));
    }  // abandoned
    EXPECT_EQ(names_in(dir.path()), std::vector<std::string>{"r.rcbscene.tmp"});
    write_streamed(r, path);
    EXPECT_EQ(read_recording(path), r);
    EXPECT_EQ(file_bytes(path + ".tmp"), "the user's notes");
    EXPECT_EQ(names_in(dir.path()), (std::vector<std::string>{"r.rcbscene", "r.rcbscene.tmp"}));
}

TEST(RecordingStream, StreamedScenesAreBoundedByOneFrameAndTheFile) {
    // 10^5 bodies over 1000 frames: far past the in-memory bound, within the streamed ones.
    EXPECT_NO_THROW(check_streamed_scene_size(1e5, 1000, 100, 1e5, "scene"));
    test::expect_input_error([] { check_scene_size(1e5, 1000, 100, 1e5, "scene"); }, "more than the limit of 4.29 GB");
    test::expect_input_error([] { check_streamed_scene_size(1e5, 10, 2e8, 1e5, "--rays"); },
                             "--rays: one frame would take 4.81 GB in memory");
    test::expect_input_error([] { check_streamed_scene_size(1e6, 2000, 100, 1e6, "--frames"); },
                             "--frames: the recording could take 90.1 GB on disk");
    // Ten frames of 10^8 rays fit the file's bound but not the rays' own.
    test::expect_input_error([] { check_streamed_scene_size(1000, 11, 1e8, 10, "--rays"); },
                             "--rays: the recording's rays could take 27.5 GB (11 frames of 100000000 rays)");
    test::expect_input_error([] { check_streamed_scene_size(1e9, 1, 1, 1, "--objects"); },
                             "more than the limit of 67108864 per scene");
}

class SceneGenCli : public ::testing::Test {
protected:
    ::test::Outcome run(const std::string& args, const ::test::RunOptions& o = {}) {
        return ::test::run_process({"/bin/sh", "-c", std::string(RCBENCH_BINARY) + " " + args}, o);
    }
    std::string path(const std::string& name) const { return dir_.file(name); }
    rcb::test::TempDir dir_{"stream_cli"};
};

TEST_F(SceneGenCli, StreamsTheSameFileAndRefusesInOneLine) {
    const ::test::Outcome ok =
        run("scene gen --generator brownian --objects 500 --frames 10 --rays 20 --seed 3 -o " + path("b.rcbscene"));
    ASSERT_EQ(ok.code, 0) << ok.err;
    EXPECT_NE(ok.out.find("500 objects, 10 frames, 200 rays"), std::string::npos) << ok.out;
    SceneSettings s;
    s.generator = "brownian";
    s.objects = 500;
    s.frames = 10;
    s.seed = 3;
    s.rays.per_frame = 20;
    EXPECT_EQ(file_bytes(path("b.rcbscene")), encode_recording(generate_scene(s)));
    for (const auto& [args, needle] :
         {std::pair<std::string, std::string>{"--generator brownian --objects 1000000 --frames 2000",
                                              "--objects/--frames/--rays: the recording could take 90.1 GB on disk"},
          {"--preset uni-s --objects 30000000 --rays 100000000", "one frame would take"}}) {
        const ::test::Outcome r = run("scene gen " + args + " -o " + path("x.rcbscene"));
        EXPECT_EQ(r.code, 2) << r.err;
        EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_FALSE(fs::exists(path("x.rcbscene")));
    }
}

TEST_F(SceneGenCli, AKilledGenerationLeavesTheNameUntouched) {
    // Killed while it simulates: the frames written so far sit in the temporary file (it streams),
    // and the file at -o is the one that was there before.
    const std::string out = path("k.rcbscene");
    std::ofstream(out) << "before";
    ::test::RunOptions o;
    o.timeout_seconds = 4;
    const ::test::Outcome r =
        run("scene gen --generator brownian --objects 2000 --frames 100000 --rays 10 -o " + out, o);
    EXPECT_TRUE(r.timed_out) << r.code << " " << r.err;
    EXPECT_EQ(file_bytes(out), "before");
    // The frames so far are in the hidden temporary file beside it, ".k.rcbscene.XXXXXX".
    const std::vector<std::string> names = names_in(fs::path(out).parent_path());
    ASSERT_EQ(names.size(), 2u);
    ASSERT_EQ(names[0].rfind(".k.rcbscene.", 0), 0u) << names[0];
    // More than the header and frame 0's 2000 objects (29 bytes each or more): frames are on disk.
    EXPECT_GT(fs::file_size(fs::path(out).parent_path() / names[0]), 2000u * 29 + 1000);
}

}  // namespace
}  // namespace rcb
