// Broadmark's scene files (core/scene/import/broadmark.h): import keeps frame 0 and the moves of
// the boxes that changed, export(import(file)) gives the file back byte for byte, rcbench's
// scenes go out and come back with the same boxes, and malformed files and scenes the format
// cannot hold are refused with one-line errors (exit 2 from the command line).
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
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

/// A Broadmark file written field by field as the format page says: `blocks` frames of the boxes
/// `frame(f, i)`, the header claiming `header_frames`.
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

TEST(Broadmark, ImportKeepsFrameZeroAndTheMovesOfChangedBoxes) {
    const std::string file = broadmark_file(4, 5, 5);
    ASSERT_EQ(file.size(), kBroadmarkHeaderBytes + 5u * 4u * 32u);
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
    EXPECT_EQ(meta["broadmark"]["frames"], 5);
}

TEST(Broadmark, FilesRoundTripByteForByte) {
    // The header's frame count equal to the frames written, or one less (the first not counted).
    for (std::uint32_t header_frames : {5u, 4u}) {
        const std::string file = broadmark_file(7, 5, header_frames);
        EXPECT_EQ(encode_broadmark(decode_broadmark(file, "b.aabbs"), "out.aabbs"), file) << header_frames;
    }
    // Through the command line: import (adding rays), then export.
    const test::TempDir dir("broadmark");
    const std::string file = broadmark_file(30, 9, 9);
    std::ofstream(dir.file("in.aabbs"), std::ios::binary) << file;
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
    std::ifstream in(dir.file("out.aabbs"), std::ios::binary);
    const std::string back((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_TRUE(back == file) << back.size() << " bytes against " << file.size();
}

TEST(Broadmark, RcbenchScenesGoOutAndComeBackWithTheirBoxes) {
    SceneSettings s;
    s.kind = "brownian";
    s.objects = 60;
    s.frames = 6;
    s.rays.per_frame = 0;
    s.shapes = {0.3, 0.3, 0.2};
    const Recording r = generate_scene(s);
    const std::string bytes = encode_broadmark(r, "x.aabbs");
    EXPECT_EQ(bytes.size(), kBroadmarkHeaderBytes + 7u * 60u * 32u);
    const Recording back = decode_broadmark(bytes, "x.aabbs");
    LiveSet a(r.initial), b(back.initial);
    for (std::size_t f = 0; f <= r.frames.size(); ++f) {
        if (f > 0) a.apply(r.frames[f - 1]), b.apply(back.frames[f - 1]);
        for (const Object& o : a.objects()) EXPECT_EQ(b.box(o.uid), o.box) << "frame " << f << " uid " << o.uid;
    }
    EXPECT_EQ(encode_broadmark(back, "y.aabbs"), bytes);
    EXPECT_EQ(nlohmann::json::parse(back.meta)["broadmark"]["scene_name"], "brownian");
}

TEST(Broadmark, MalformedFilesAreRefused) {
    const std::string good = broadmark_file(3, 2, 2);
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
        {with(256, u32(0)), "object count 0"},
        {with(256, u32(0x80000000u)), "object count -2147483648"},
        {with(260, u32(0)), "frame count 0"},
        {with(264, u32(1)), "padding integers"},
        {with(272 + 12, f32(1)), "world box: the fourth float"},
        {good + "x", "are not 2 or 3 frames of 3 boxes"},
        {good.substr(0, good.size() - 32), "are not 2 or 3 frames"},
        {with(256, u32(4)), "frames of 4 boxes"},
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
    const test::TempDir dir("broadmark");
    std::ofstream(dir.file("in.aabbs"), std::ios::binary) << broadmark_file(3, 2, 2);
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
    // A Broadmark file carries its motion: --frames and the change options are refused, and the
    // static-scene importer (experiment files' "import") points to `scene import`.
    const ::test::Outcome f =
        ::test::run_shell(bin + " scene import " + dir.file("in.aabbs") + " --frames 3 -o " + dir.file("s.rcbscene"));
    EXPECT_EQ(f.code, 2) << f.err;
    EXPECT_NE(f.err.find("--frames: a Broadmark file carries its own frames"), std::string::npos) << f.err;
    EXPECT_EQ(importer_for("x.AABBS"), "broadmark");
    test::expect_input_error([&] { import_objects(dir.file("in.aabbs"), ImportOptions{}); }, "carries its own motion");
}

}  // namespace
}  // namespace rcb
