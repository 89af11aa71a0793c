// Broadmark's scene files (core/scene/import/broadmark.h): import keeps frame 0 and the moves of
// the boxes that changed, export(import(file)) gives the file back byte for byte, every export
// passes Broadmark's own reader rules (Core/Scene.h), rcbench's scenes go out and come back with
// the same boxes, --frames and --objects take the first part of a file, and malformed files,
// budgets exceeded and scenes the format cannot hold are refused with one-line errors (exit 2
// from the command line).
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/import/broadmark.h"
#include "core/scene/import/scene_import.h"
#include "core/scene/recording_io.h"
#include "tests/subprocess.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

void put_u32(std::string& out, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) out += char((v >> (8 * i)) & 0xff);
}
void put_f32(std::string& out, float v) { put_u32(out, std::bit_cast<std::uint32_t>(v)); }
void put_box(std::string& out, const Aabb& b) {
    for (float v : {b.min.x, b.min.y, b.min.z, 0.0f, b.max.x, b.max.y, b.max.z, 0.0f}) put_f32(out, v);
}
void put_name(std::string& out, const std::string& s) {
    out += s;
    out.append(128 - s.size(), '\0');
}

/// A Broadmark file written byte by byte by Broadmark's layout (its generator's AABBsRecorder.cs:
/// the header, frame 0's boxes, then one block per frame; the header counts the latter), without
/// rcbench's writer: `blocks` blocks of the boxes below, the header claiming `header_frames`.
std::string broadmark_file(std::uint32_t n, std::uint32_t blocks, std::uint32_t header_frames) {
    std::string b;
    put_name(b, "Brownian");
    put_name(b, "Cubes");
    put_u32(b, n);
    put_u32(b, header_frames);
    put_u32(b, 0), put_u32(b, 0);
    put_box(b, {{-50, -50, -50}, {50, 50, 50}});
    for (std::uint32_t f = 0; f < blocks; ++f)
        for (std::uint32_t i = 0; i < n; ++i) {
            // Object i moves in frames where f % (i + 1) == 0; -0.0 in one corner must survive.
            const float shift = float(f / (i + 1)) * 0.25f, x = float(i) * 2;
            put_box(b, {{x + shift, i == 0 ? -0.0f : 0.0f, 0}, {x + 1 + shift, 1, 1}});
        }
    return b;
}

std::uint32_t u32_at(const std::string& b, std::size_t at) {
    std::uint32_t v = 0;
    for (int i = 3; i >= 0; --i) v = v << 8 | static_cast<unsigned char>(b[at + std::size_t(i)]);
    return v;
}
float f32_at(const std::string& b, std::size_t at) { return std::bit_cast<float>(u32_at(b, at)); }

/// What Broadmark's reader (Core/Scene.h: Scene::Scene, ValidateHeader, ValidateString,
/// ValidateFrame; Core/Math/Aabb.h: Aabb::Validate) would abort on, or "" when it reads the file.
std::string broadmark_reader_problem(const std::string& b) {
    if (b.size() <= 304) return "not larger than the header";
    for (std::size_t field : {0u, 128u}) {  // ValidateString over 127 bytes, and strlen <= 127
        std::size_t i = 0;
        while (i < 127 && b[field + i] != 0) {
            if (!std::isprint(static_cast<unsigned char>(b[field + i]))) return "unprintable name byte";
            ++i;
        }
        if (i == 0) return "empty name";
        if (i == 127 && b[field + 127] != 0) return "name longer than 127 bytes";
        for (; i < 127; ++i)
            if (b[field + i] != 0) return "name padding not 0";
    }
    const auto n = std::int32_t(u32_at(b, 256)), frames = std::int32_t(u32_at(b, 260));
    if (n <= 0 || frames <= 0) return "N or frames not positive";
    if (u32_at(b, 264) != 0 || u32_at(b, 268) != 0) return "padding integers not 0";
    if (b.size() != 304 + 32 * std::uint64_t(n) * (1 + std::uint64_t(frames)))
        return "size not 304 + 32 N (1 + frames)";
    for (std::size_t at = 272; at < b.size(); at += 32) {
        if (f32_at(b, at + 12) != 0.0f || f32_at(b, at + 28) != 0.0f) return "a 4th float not 0";
        for (std::size_t a = 0; a < 3; ++a)
            if (!(f32_at(b, at + 4 * a) <= f32_at(b, at + 16 + 4 * a))) return "min > max";
    }
    return "";
}

std::string read_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {(std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()};
}

TEST(Broadmark, ImportKeepsFrameZeroAndTheMovesOfChangedBoxes) {
    const std::string file = broadmark_file(4, 5, 4);
    ASSERT_EQ(file.size(), kBroadmarkHeaderBytes + 5u * 4u * 32u);
    ASSERT_EQ(broadmark_reader_problem(file), "");
    const Recording r = decode_broadmark(file, "b.aabbs");
    ASSERT_EQ(r.initial.size(), 4u);
    ASSERT_EQ(r.frames.size(), 4u);
    for (Uid i = 0; i < 4; ++i) EXPECT_EQ(r.initial[i].uid, i);
    EXPECT_EQ(r.initial[2].box, (Aabb{{4, 0, 0}, {5, 1, 1}}));
    EXPECT_TRUE(std::signbit(r.initial[0].box.min.y));
    // Frame 1 moves object 0 only (1 / 1 changes, 1 / 2 = 0 keeps the others); frame 2 moves 0 and 1.
    ASSERT_EQ(r.frames[0].moves.size(), 1u);
    EXPECT_EQ(r.frames[0].moves[0].uid, 0u);
    EXPECT_EQ(r.frames[0].moves[0].box.min.x, 0.25f);
    ASSERT_EQ(r.frames[1].moves.size(), 2u);
    EXPECT_EQ(r.frames[1].moves[1].uid, 1u);
    for (const Frame& f : r.frames) EXPECT_TRUE(f.rays.empty());
    const auto meta = nlohmann::json::parse(r.meta);
    EXPECT_EQ(meta["broadmark"]["scene_name"], "Brownian");
    EXPECT_EQ(meta["broadmark"]["object_type"], "Cubes");
    EXPECT_EQ(meta["broadmark"]["frames"], 4);
    // The first frames and objects only.
    BroadmarkLimits part;
    part.frames = 2;
    part.objects = 3;
    const Recording p = decode_broadmark(file, "b.aabbs", part);
    ASSERT_EQ(p.initial.size(), 3u);
    ASSERT_EQ(p.frames.size(), 2u);
    EXPECT_EQ(p.frames[1].moves.size(), 2u);
    EXPECT_EQ(p.initial[2].box, r.initial[2].box);
    part.frames = 0;  // frame 0 alone
    EXPECT_TRUE(decode_broadmark(file, "b.aabbs", part).frames.empty());
}

TEST(Broadmark, FilesRoundTripByteForByte) {
    const std::string file = broadmark_file(7, 5, 4);
    EXPECT_EQ(encode_broadmark(decode_broadmark(file, "b.aabbs"), "out.aabbs"), file);
    // Through the command line: import (adding rays), then export.
    const test::TempDir dir("broadmark");
    const std::string big = broadmark_file(30, 9, 8);
    std::ofstream(dir.file("in.aabbs"), std::ios::binary) << big;
    const std::string bin = RCBENCH_BINARY;
    const ::test::Outcome imp =
        ::test::run_shell(bin + " scene import " + dir.file("in.aabbs") + " --rays 20 -o " + dir.file("s.rcbscene"));
    ASSERT_EQ(imp.code, 0) << imp.err;
    const Recording r = read_recording(dir.file("s.rcbscene"));
    ASSERT_EQ(r.frames.size(), 8u);
    for (const Frame& f : r.frames) EXPECT_EQ(f.rays.size(), 20u);
    const ::test::Outcome ex = ::test::run_shell(bin + " scene export " + dir.file("s.rcbscene") +
                                                 " --format broadmark -o " + dir.file("out.aabbs"));
    ASSERT_EQ(ex.code, 0) << ex.err;
    EXPECT_NE(ex.out.find("30 objects, frame 0 and 8 frames after it"), std::string::npos) << ex.out;
    const std::string back = read_bytes(dir.file("out.aabbs"));
    EXPECT_TRUE(back == big) << back.size() << " bytes against " << big.size();
}

TEST(Broadmark, EveryExportPassesBroadmarksReader) {
    // A file written byte by byte by Broadmark's layout, imported whole and in parts (--frames,
    // --objects), then exported: each export is what Broadmark's reader accepts, with the frames
    // and objects taken.
    const test::TempDir dir("broadmark");
    const std::string file = broadmark_file(12, 7, 6);
    ASSERT_EQ(broadmark_reader_problem(file), "");
    std::ofstream(dir.file("in.aabbs"), std::ios::binary) << file;
    const std::string bin = RCBENCH_BINARY;
    struct Part {
        std::string options;
        std::uint32_t objects, frames;
    };
    for (const Part& p : {Part{"", 12, 6}, Part{"--frames 1", 12, 1}, Part{"--frames 4 --objects 5", 5, 4},
                          Part{"--objects 1", 1, 6}}) {
        SCOPED_TRACE(p.options);
        const ::test::Outcome imp = ::test::run_shell(bin + " scene import " + dir.file("in.aabbs") + " " + p.options +
                                                      " --rays 3 -o " + dir.file("s.rcbscene"));
        ASSERT_EQ(imp.code, 0) << imp.err;
        const ::test::Outcome ex = ::test::run_shell(bin + " scene export " + dir.file("s.rcbscene") +
                                                     " --format broadmark -o " + dir.file("out.aabbs"));
        ASSERT_EQ(ex.code, 0) << ex.err;
        const std::string out = read_bytes(dir.file("out.aabbs"));
        EXPECT_EQ(broadmark_reader_problem(out), "");
        EXPECT_EQ(u32_at(out, 256), p.objects);
        EXPECT_EQ(u32_at(out, 260), p.frames);
        // The boxes are the file's: object i of block f at the same bytes.
        for (std::uint32_t f = 0; f <= p.frames; ++f)
            for (std::uint32_t i = 0; i < p.objects; ++i)
                ASSERT_EQ(out.substr(304 + 32 * (std::size_t(f) * p.objects + i), 32),
                          file.substr(304 + 32 * (std::size_t(f) * 12 + i), 32))
                    << "frame " << f << " object " << i;
        std::filesystem::remove(dir.file("s.rcbscene"));
        std::filesystem::remove(dir.file("out.aabbs"));
    }
    // rcbench's own scenes, of every generator that keeps its objects, pass too.
    for (const char* generator : {"pile", "brownian", "gravity"}) {
        SCOPED_TRACE(generator);
        SceneSettings s;
        s.generator = generator;
        s.objects = 40;
        s.frames = 3;
        s.rays.per_frame = 0;
        const std::string out = encode_broadmark(generate_scene(s), "x.aabbs");
        EXPECT_EQ(broadmark_reader_problem(out), "");
        EXPECT_EQ(u32_at(out, 260), 3u);
    }
}

TEST(Broadmark, RcbenchScenesGoOutAndComeBackWithTheirBoxes) {
    SceneSettings s;
    s.generator = "pile";
    s.objects = 60;
    s.frames = 6;
    s.rays.per_frame = 0;
    s.shapes = {0.3, 0.3, 0.2};
    const Recording r = generate_scene(s);
    const std::string bytes = encode_broadmark(r, "x.aabbs");
    // Frame 0 and 6 frames after it; the header counts the 6 (Broadmark's reader: 304 + 32 N (1 + 6)).
    EXPECT_EQ(bytes.size(), kBroadmarkHeaderBytes + 7u * 60u * 32u);
    EXPECT_EQ(u32_at(bytes, 260), 6u);
    EXPECT_EQ(broadmark_reader_problem(bytes), "");
    const Recording back = decode_broadmark(bytes, "x.aabbs");
    LiveSet a(r.initial), b(back.initial);
    for (std::size_t f = 0; f <= r.frames.size(); ++f) {
        if (f > 0) a.apply(r.frames[f - 1]), b.apply(back.frames[f - 1]);
        for (const Object& o : a.objects()) EXPECT_EQ(b.box(o.uid), o.box) << "frame " << f << " uid " << o.uid;
    }
    EXPECT_EQ(encode_broadmark(back, "y.aabbs"), bytes);
    EXPECT_EQ(nlohmann::json::parse(back.meta)["broadmark"]["scene_name"], "pile");
}

TEST(Broadmark, MalformedFilesAreRefused) {
    const std::string good = broadmark_file(3, 2, 1);
    auto with = [&](std::size_t at, const std::string& bytes) {
        std::string b = good;
        b.replace(at, bytes.size(), bytes);
        return b;
    };
    auto f32 = [](float v) {
        std::string s;
        put_f32(s, v);
        return s;
    };
    auto u32 = [](std::uint32_t v) {
        std::string s;
        put_u32(s, v);
        return s;
    };
    const std::size_t box0 = kBroadmarkHeaderBytes;
    const std::vector<std::pair<std::string, std::string>> cases = {
        {good.substr(0, 100), "shorter than a Broadmark header"},
        {std::string(128, 'a') + good.substr(128), "scene name: no NUL"},
        {with(0, std::string(1, '\0')), "scene name: empty"},
        {with(130, "\x01"), "object type: byte 2 is not a printable character"},
        {with(200, "x"), "object type: byte 72 after the NUL is not 0"},
        {with(256, u32(0)), "object count 0"},
        {with(256, u32(0x80000000u)), "object count -2147483648"},
        {with(260, u32(0)), "frame count 0"},
        {with(264, u32(1)), "padding integers"},
        {with(272 + 12, f32(1)), "world box: the fourth float"},
        {good + "x", "497 bytes, but a header of 3 objects and 1 frames needs 304 + 32 x 3 x (1 + 1) = 496"},
        {good.substr(0, good.size() - 32), "464 bytes, but a header of 3 objects and 1 frames needs"},
        // The count of an older rcbench export, frame 0 included: Broadmark's reader refuses it.
        {with(260, u32(2)), "a header of 3 objects and 2 frames needs 304 + 32 x 3 x (1 + 2) = 592"},
        {with(256, u32(4)), "a header of 4 objects"},
        {with(box0 + 32 + 28, f32(-0.0f)), "frame 0: object 1: the fourth float"},
        {with(box0 + 96, f32(std::numeric_limits<float>::quiet_NaN())), "frame 1: object 0: non-finite"},
        {with(box0 + 96, f32(1e30f)), "frame 1: object 0: coordinate"},
        {with(box0 + 64, f32(100)), "frame 0: object 2: min > max on axis x"},
    };
    for (const auto& c : cases)  // not a structured binding: clang 14 cannot capture one in a lambda
        test::expect_input_error([&] { decode_broadmark(c.first, "bad.aabbs"); }, c.second);
    // The command line: exit 2 with the file's name, and nothing written.
    const test::TempDir dir("broadmark");
    std::ofstream(dir.file("bad.aabbs"), std::ios::binary) << with(260, u32(0));
    const std::string bin = RCBENCH_BINARY;
    const ::test::Outcome o =
        ::test::run_shell(bin + " scene import " + dir.file("bad.aabbs") + " -o " + dir.file("s.rcbscene"));
    EXPECT_EQ(o.code, 2) << o.err;
    EXPECT_NE(o.err.find("bad.aabbs: Broadmark header: frame count 0"), std::string::npos) << o.err;
    EXPECT_FALSE(std::filesystem::exists(dir.file("s.rcbscene")));
    test::expect_input_error([&] { read_broadmark(dir.file("bad.aabbs")); }, "frame count 0");
}

TEST(Broadmark, WhatTheFormatCannotHoldIsRefused) {
    // Inserts and removes: Broadmark's N is fixed.
    SceneSettings s = preset_settings("uni-s");
    s.frames = 3;
    s.rays.per_frame = 0;
    s.dynamics.change_fraction = 0.1;
    test::expect_input_error([&] { encode_broadmark(generate_scene(s), "x.aabbs"); },
                             "x.aabbs: frame 1 inserts or removes objects");
    // Frame 0 alone: Broadmark's reader needs frames > 0.
    s.frames = 0;
    s.dynamics.change_fraction = 0;
    test::expect_input_error([&] { encode_broadmark(generate_scene(s), "x.aabbs"); },
                             "x.aabbs: the recording has only frame 0");
    const test::TempDir dir("broadmark");
    std::ofstream(dir.file("in.aabbs"), std::ios::binary) << broadmark_file(3, 2, 1);
    const std::string bin = RCBENCH_BINARY;
    ASSERT_EQ(::test::run_shell(bin + " scene gen --preset uni-s --frames 2 --change-fraction 0.2 -o " +
                                dir.file("u.rcbscene"))
                  .code,
              0);
    const ::test::Outcome ex = ::test::run_shell(bin + " scene export " + dir.file("u.rcbscene") +
                                                 " --format broadmark -o " + dir.file("u.aabbs"));
    EXPECT_EQ(ex.code, 2) << ex.err;
    EXPECT_NE(ex.err.find("inserts or removes"), std::string::npos) << ex.err;
    EXPECT_FALSE(std::filesystem::exists(dir.file("u.aabbs")));
    ASSERT_EQ(
        ::test::run_shell(bin + " scene import " + dir.file("in.aabbs") + " --frames 0 -o " + dir.file("zero.rcbscene"))
            .code,
        0);
    const ::test::Outcome zero = ::test::run_shell(bin + " scene export " + dir.file("zero.rcbscene") +
                                                   " --format broadmark -o " + dir.file("zero.aabbs"));
    EXPECT_EQ(zero.code, 2) << zero.err;
    EXPECT_NE(zero.err.find("only frame 0"), std::string::npos) << zero.err;
    EXPECT_EQ(std::count(zero.err.begin(), zero.err.end(), '\n'), 1) << zero.err;
    EXPECT_FALSE(std::filesystem::exists(dir.file("zero.aabbs")));
    // A Broadmark file carries its motion: the change options are refused, --frames and --objects
    // beyond the file too; the static-scene importer (experiment files' "import") points to
    // `scene import`, and --objects is for Broadmark files only.
    for (const auto& [options, message] : std::vector<std::pair<std::string, std::string>>{
             {"--change-fraction 0.1", "--change-fraction: a Broadmark file carries its own motion"},
             {"--frames 2", "--frames 2: the file has 1 frames after frame 0"},
             {"--objects 4", "--objects 4: the file has 3 objects"}}) {
        const ::test::Outcome f = ::test::run_shell(bin + " scene import " + dir.file("in.aabbs") + " " + options +
                                                    " -o " + dir.file("s.rcbscene"));
        EXPECT_EQ(f.code, 2) << f.err;
        EXPECT_NE(f.err.find(message), std::string::npos) << f.err;
        EXPECT_FALSE(std::filesystem::exists(dir.file("s.rcbscene")));
    }
    std::ofstream(dir.file("b.csv")) << "0,0,0,0,1,1,1\n";
    const ::test::Outcome csv =
        ::test::run_shell(bin + " scene import " + dir.file("b.csv") + " --objects 1 -o " + dir.file("s.rcbscene"));
    EXPECT_EQ(csv.code, 2) << csv.err;
    EXPECT_NE(csv.err.find("--objects: only for a Broadmark scene file"), std::string::npos) << csv.err;
    EXPECT_EQ(importer_for("x.AABBS"), "broadmark");
    test::expect_input_error([&] { import_objects(dir.file("in.aabbs"), ImportOptions{}); }, "carries its own motion");
}

TEST(Broadmark, ImportNamesTheMemoryBudgetAndHowToStayUnderIt) {
    // 10^8 rays a frame over 2 frames is over the 4.29 GB budget; one frame is not.
    const std::string file = broadmark_file(3, 3, 2);
    BroadmarkLimits limits;
    limits.rays_per_frame = 100'000'000;
    test::expect_input_error([&] { decode_broadmark(file, "big.aabbs", limits); },
                             "big.aabbs: 3 objects and 2 frames (every object moving, 100000000 rays a frame) would "
                             "take");
    test::expect_input_error([&] { decode_broadmark(file, "big.aabbs", limits); },
                             "over the memory budget of 4.29 GB; to stay under it take --frames 1 or fewer");
    limits.frames = 1;
    EXPECT_EQ(decode_broadmark(file, "big.aabbs", limits).frames.size(), 1u);
}

}  // namespace
}  // namespace rcb
