// The recording file: round trip, determinism, and every kind of corruption rejected with a
// message naming the file, the frame and the uid or ray; version 2 with shapes.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

Recording small_recording() {
    SceneSettings s = preset_settings("irreg-s");
    s.frames = 5;
    s.rays.per_frame = 20;
    return generate_scene(s);
}

std::string file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

/// How many files the folder holds.
std::size_t entries(const test::TempDir& dir) {
    return std::size_t(std::distance(std::filesystem::directory_iterator(dir.path()), {}));
}

std::string error_of(const std::string& bytes) {
    return test::input_error_of([&] { decode_recording(bytes, "scene.rcbscene"); });
}

std::string error_of(const Recording& r) { return error_of(encode_recording(r)); }

TEST(Recording, RoundTripsThroughAFile) {
    const Recording r = small_recording();
    const test::TempDir dir("recording", "roundtrip");
    const std::string path = dir.file("r.rcbscene");
    write_recording(r, path);
    EXPECT_EQ(read_recording(path), r);
    EXPECT_EQ(entries(dir), 1u);  // no temporary file left
}

TEST(Recording, WritingLeavesTheUsersOtherFilesAlone) {
    // The temporary file has a name of its own, unique in the folder: a file of the user's named
    // like a temporary file ("<path>.tmp") is neither written over nor removed.
    const Recording r = small_recording();
    const test::TempDir dir("recording", "neighbours");
    const std::string path = dir.file("r.rcbscene");
    std::ofstream(path + ".tmp") << "the user's notes";
    write_recording(r, path);
    EXPECT_EQ(read_recording(path), r);
    EXPECT_EQ(file_bytes(path + ".tmp"), "the user's notes");
    write_recording(r, path);  // over an existing recording too
    EXPECT_EQ(file_bytes(path + ".tmp"), "the user's notes");
    EXPECT_EQ(entries(dir), 2u);
    // Refused: nothing is written, the user's file stays.
    Recording bad = r;
    bad.initial[1].uid = bad.initial[0].uid;
    EXPECT_THROW(write_recording(bad, path), InputError);
    EXPECT_EQ(file_bytes(path + ".tmp"), "the user's notes");
    EXPECT_EQ(read_recording(path), r);
    EXPECT_EQ(entries(dir), 2u);
}

TEST(Recording, HeaderIsLittleEndianAndVersioned) {
    const std::string bytes = encode_recording(small_recording());
    EXPECT_EQ(bytes.substr(0, 8), "RCBSCENE");
    EXPECT_EQ(bytes[8], 1);  // version 1, little-endian
    EXPECT_EQ(bytes[9], 0);
    EXPECT_EQ(std::uint8_t(bytes[12]), 0x04);  // byte-order mark 0x01020304, low byte first
}

TEST(Recording, RejectsBadMagicVersionAndChecksum) {
    std::string bytes = encode_recording(small_recording());
    std::string bad = bytes;
    bad[0] = 'X';
    EXPECT_NE(error_of(bad).find("not an rcbench scene recording"), std::string::npos);
    bad = bytes;
    bad[8] = 9;
    EXPECT_NE(error_of(bad).find("format version 9 is not supported"), std::string::npos);
    bad = bytes;
    bad[bytes.size() / 2] ^= 0x40;  // inside a payload
    EXPECT_NE(error_of(bad).find("checksum mismatch"), std::string::npos) << error_of(bad);
}

TEST(Recording, EveryTruncationIsAnErrorNeverACrash) {
    const std::string bytes = encode_recording(small_recording());
    for (std::size_t cut = 0; cut < bytes.size(); cut += 1 + cut / 50) {
        const std::string message = error_of(bytes.substr(0, cut));
        ASSERT_FALSE(message.empty()) << "truncated at " << cut << " was accepted";
        EXPECT_EQ(message.find("scene.rcbscene"), 0u) << message;
    }
    EXPECT_NE(error_of(bytes.substr(0, bytes.size() - 16)).find("truncated"), std::string::npos);
}

TEST(Recording, RandomByteFlipsAreRejectedNeverACrash) {
    const std::string bytes = encode_recording(small_recording());
    std::uint64_t x = 12345;
    for (int i = 0; i < 2000; ++i) {
        x = x * 6364136223846793005ULL + 1442695040888963407ULL;
        std::string bad = bytes;
        bad[(x >> 20) % bad.size()] ^= char(1 + (x >> 8) % 255);
        EXPECT_FALSE(error_of(bad).empty()) << "flip " << i << " accepted";
    }
}

TEST(Recording, RejectsDuplicateAndUnknownUidsNamingFrameAndUid) {
    Recording r = small_recording();
    Recording dup = r;
    dup.initial[3].uid = dup.initial[4].uid;
    EXPECT_EQ(error_of(dup), "scene.rcbscene: frame 0: duplicate uid " + std::to_string(r.initial[4].uid));

    Recording rem = r;
    rem.frames[2].removes.push_back(999999);
    EXPECT_EQ(error_of(rem), "scene.rcbscene: frame 3: remove of unknown uid 999999");

    Recording mov = r;
    mov.frames[1].moves.push_back({888888, {{0, 0, 0}, {1, 1, 1}}});
    EXPECT_EQ(error_of(mov), "scene.rcbscene: frame 2: move of unknown uid 888888");

    Recording ins = r;
    ins.frames[0].inserts.push_back({r.initial[0].uid, {{0, 0, 0}, {1, 1, 1}}});
    EXPECT_NE(error_of(ins).find("frame 1: "), std::string::npos);
    EXPECT_NE(error_of(ins).find("uid " + std::to_string(r.initial[0].uid)), std::string::npos);
}

TEST(Recording, RejectsNonFiniteCoordinatesAndInvertedBoxes) {
    Recording r = small_recording();
    Recording nan = r;
    nan.initial[7].box.min.y = std::nanf("");
    EXPECT_EQ(error_of(nan),
              "scene.rcbscene: frame 0: uid " + std::to_string(r.initial[7].uid) + ": non-finite coordinate");

    Recording inf = r;
    inf.frames[3].moves.at(0).box.max.z = INFINITY;
    EXPECT_EQ(error_of(inf),
              "scene.rcbscene: frame 4: uid " + std::to_string(r.frames[3].moves[0].uid) + ": non-finite coordinate");

    Recording inverted = r;
    std::swap(inverted.initial[2].box.min.x, inverted.initial[2].box.max.x);
    EXPECT_EQ(error_of(inverted),
              "scene.rcbscene: frame 0: uid " + std::to_string(r.initial[2].uid) + ": min > max on axis x");

    Recording ray = r;
    ray.frames[1].rays[5].p1.x = std::nanf("");
    EXPECT_EQ(error_of(ray), "scene.rcbscene: frame 2: ray 5: non-finite coordinate");
}

TEST(Recording, RejectsCoordinatesBeyondTheLimitNamingFrameAndUid) {
    Recording r = small_recording();
    const std::string limit = " beyond ±1e+15 (the largest magnitude every structure handles exactly)";
    Recording big = r;
    big.initial[7].box.max.x = 1e20f;  // a box 1e20 long: Embree asserted on the rays reaching it
    EXPECT_EQ(error_of(big),
              "scene.rcbscene: frame 0: uid " + std::to_string(r.initial[7].uid) + ": coordinate 1e+20" + limit);
    Recording far = r;
    far.frames[2].moves.at(0).box = {{-3e38f, 0, 0}, {-3e38f, 1, 1}};
    EXPECT_EQ(error_of(far), "scene.rcbscene: frame 3: uid " + std::to_string(r.frames[2].moves[0].uid) +
                                 ": coordinate -3e+38" + limit);
    Recording ray = r;
    ray.frames[0].rays[3].p0.z = 2e15f;
    EXPECT_EQ(error_of(ray), "scene.rcbscene: frame 1: ray 3: coordinate 2e+15" + limit);
    Recording tiny = r;
    tiny.initial[7].box.min.y = 3e-25f;  // nonzero but below kMinCoordinate
    EXPECT_EQ(error_of(tiny),
              "scene.rcbscene: frame 0: uid " + std::to_string(r.initial[7].uid) +
                  ": coordinate 3e-25 below 1e-20 in magnitude (write 0: float arithmetic is not exact that small)");
    Recording denormal = r;
    denormal.frames[1].rays[0].p1.y = -1e-42f;  // brute force itself disagreed with the ground truth here
    EXPECT_NE(error_of(denormal).find("scene.rcbscene: frame 2: ray 0: coordinate -1.00053e-42 below 1e-20"),
              std::string::npos)
        << error_of(denormal);
    // At the limits is fine.
    Recording edge = r;
    edge.initial[7].box = {{-1e15f, -1e15f, -1e-20f}, {1e15f, 1e15f, 1e15f}};
    edge.frames[0].rays[3] = {{-1e15f, 0, 0}, {1e15f, 0, 0}};
    EXPECT_EQ(error_of(edge), "");
}

TEST(Recording, TheWriterRefusesWhatTheReaderWouldReject) {
    // A scene with coordinates near ±3e38 was written, and then refused by rcbench's own reader.
    Recording r = small_recording();
    r.initial[2].box = {{-3e38f, 0, 0}, {3e38f, 1, 1}};
    const test::TempDir dir("recording", "refused");
    const std::string path = dir.file("r.rcbscene");
    const std::string m = test::input_error_of([&] { write_recording(r, path); });
    EXPECT_EQ(m.rfind(path + " (not written): frame 0: uid " + std::to_string(r.initial[2].uid) +
                          ": coordinate -3e+38 beyond ±1e+15",
                      0),
              0u)
        << m;
    EXPECT_FALSE(std::filesystem::exists(path));
    EXPECT_EQ(entries(dir), 0u);  // no temporary file either
    Recording dup = small_recording();
    dup.initial[1].uid = dup.initial[0].uid;
    EXPECT_THROW(write_recording(dup, path), InputError);
    EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(Recording, UnknownSectionTagsAreQuotedAndEscaped) {
    std::string bytes = encode_recording(small_recording());
    const std::size_t objs = bytes.find("OBJS");
    ASSERT_NE(objs, std::string::npos);
    bytes.replace(objs, 4, "\x1b[2J");
    EXPECT_NE(error_of(bytes).find(": unknown section tag '\\x1B[2J' at offset"), std::string::npos) << error_of(bytes);
}

TEST(Recording, ReadingAMissingFileOrAFolderIsAnInputError) {
    EXPECT_THROW(read_recording("/nonexistent/scene.rcbscene"), InputError);
    EXPECT_THROW(read_recording(std::filesystem::temp_directory_path().string()), InputError);
}

Recording shaped_recording() { return test::with_shapes(test::generated_scene("irregular", 300, 4, 5), 9); }

TEST(Recording, Version2RoundTripsShapesAndVersion1StillReads) {
    const Recording shaped = shaped_recording();
    EXPECT_EQ(recording_version(shaped), 2u);
    EXPECT_EQ(decode_recording(encode_recording(shaped), "shaped"), shaped);
    const Recording boxes = test::generated_scene("irregular", 100, 2, 5);
    const std::string bytes = encode_recording(boxes);
    EXPECT_EQ(recording_version(boxes), 1u);
    EXPECT_EQ(bytes[8], 1);  // a box scene is still written as version 1, byte for byte as before
    EXPECT_EQ(decode_recording(bytes, "boxes"), boxes);
}

TEST(Recording, BadShapesAreRejectedNamingFileAndObject) {
    Recording r = shaped_recording();
    std::string bytes = encode_recording(r);
    // Patch the first shaped object's first float to NaN, then fix the section's checksum by
    // re-encoding through a recording whose shape is invalid: refuse_invalid_recording must refuse it.
    for (Object& o : r.initial)
        if (o.shape.kind == ShapeKind::triangle) {
            o.shape.v[0] = std::nanf("");
            const std::string m = test::input_error_of([&] { refuse_invalid_recording(r, "scene.rcbscene"); });
            EXPECT_NE(m.find("scene.rcbscene"), std::string::npos) << m;
            EXPECT_NE(m.find("uid " + std::to_string(o.uid)), std::string::npos) << m;
            EXPECT_NE(m.find("non-finite"), std::string::npos) << m;
            EXPECT_EQ(m.find('\n'), std::string::npos);
            o.shape.v[0] = 0;
            o.box = Aabb{{0, 0, 0}, {1, 1, 1}};  // a box that is not the shape's bounds
            EXPECT_THROW(refuse_invalid_recording(r, "scene.rcbscene"), InputError);
            break;
        }
    // An unknown kind byte in the file (with the section's checksum made right again).
    const std::size_t objs = bytes.find("OBJS"), payload = objs + 4 + 8 + 4;
    std::uint64_t length = 0;
    for (int i = 0; i < 8; ++i) length |= std::uint64_t(std::uint8_t(bytes[objs + 4 + i])) << (8 * i);
    bytes[payload + 4 + 4] = 9;  // after the count and the first uid
    const auto crc = std::uint32_t(crc32(0, reinterpret_cast<const Bytef*>(bytes.data() + payload), uInt(length)));
    for (int i = 0; i < 4; ++i) bytes[objs + 12 + i] = char((crc >> (8 * i)) & 0xff);
    test::expect_input_error([&] { decode_recording(bytes, "scene.rcbscene"); }, "unknown shape kind 9");
}

}  // namespace
}  // namespace rcb
