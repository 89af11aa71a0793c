#include "core/scene/import/broadmark.h"

#include <bit>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <unordered_map>

#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "core/base/output_file.h"
#include "core/scene/recording_io.h"

namespace rcb {
namespace {

constexpr std::size_t kNameBytes = 128;
constexpr std::size_t kBoxBytes = 32;  // min x y z 0, max x y z 0

std::uint32_t u32_at(const std::string& b, std::size_t at) {
    return std::uint32_t(static_cast<unsigned char>(b[at])) |
           std::uint32_t(static_cast<unsigned char>(b[at + 1])) << 8 |
           std::uint32_t(static_cast<unsigned char>(b[at + 2])) << 16 |
           std::uint32_t(static_cast<unsigned char>(b[at + 3])) << 24;
}
float f32_at(const std::string& b, std::size_t at) { return std::bit_cast<float>(u32_at(b, at)); }

void put_u32(std::string& out, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) out += char((v >> (8 * i)) & 0xff);
}
void put_f32(std::string& out, float v) { put_u32(out, std::bit_cast<std::uint32_t>(v)); }

struct Header {
    std::string scene_name, object_type;
    std::uint32_t objects = 0, frames = 0;
    Aabb world;
};

/// A box of 8 floats at `at`: min x y z, a zero pad, max x y z, a zero pad (both pads bit for bit
/// +0, as Broadmark's generator writes them). `where` names it in messages.
Aabb box_at(const std::string& b, std::size_t at, const std::string& where) {
    if (u32_at(b, at + 12) != 0 || u32_at(b, at + 28) != 0)
        throw InputError(where + ": the fourth float of min or max is not 0 (Broadmark pads each point with a 0)");
    const Aabb box{{f32_at(b, at), f32_at(b, at + 4), f32_at(b, at + 8)},
                   {f32_at(b, at + 16), f32_at(b, at + 20), f32_at(b, at + 24)}};
    if (const std::string problem = box_problem(box); !problem.empty()) throw InputError(where + ": " + problem);
    return box;
}

/// The string of a 128-byte field as Broadmark's reader checks it (Core/Scene.h,
/// Scene::ValidateString over the first 127 bytes): at least one printable character, then a NUL
/// and only NULs up to byte 127. Byte 128 must be a NUL too (rcbench's rule: the string ends
/// inside its field).
std::string name_at(const std::string& b, std::size_t at, const std::string& where) {
    const void* nul = std::memchr(b.data() + at, 0, kNameBytes);
    if (!nul) throw InputError(where + ": no NUL within its 128 bytes (not a Broadmark scene file?)");
    const std::size_t len = static_cast<const char*>(nul) - (b.data() + at);
    if (len == 0) throw InputError(where + ": empty (Broadmark's reader needs at least one character)");
    for (std::size_t i = 0; i < kNameBytes; ++i) {
        const auto c = static_cast<unsigned char>(b[at + i]);
        if (i < len && !std::isprint(c))
            throw InputError(where + ": byte " + std::to_string(i) + " is not a printable character");
        if (i > len && c != 0) throw InputError(where + ": byte " + std::to_string(i) + " after the NUL is not 0");
    }
    return b.substr(at, len);
}

/// Parses and checks the header against the file's size as Broadmark's reader does (Core/Scene.h,
/// Scene::Scene): the data must be exactly 1 + frames blocks of N boxes.
Header parse_header(const std::string& b, std::uint64_t file_size, const std::string& name) {
    if (b.size() < kBroadmarkHeaderBytes)
        throw InputError(name + ": " + std::to_string(b.size()) + " bytes, shorter than a Broadmark header (304)");
    Header h;
    h.scene_name = name_at(b, 0, name + ": Broadmark header: scene name");
    h.object_type = name_at(b, kNameBytes, name + ": Broadmark header: object type");
    const std::int32_t n = std::bit_cast<std::int32_t>(u32_at(b, 256));
    const std::int32_t frames = std::bit_cast<std::int32_t>(u32_at(b, 260));
    if (n <= 0 || std::uint64_t(n) > kMaxSceneObjects)
        throw InputError(name + ": Broadmark header: object count " + std::to_string(n) + " is not in 1.." +
                         std::to_string(kMaxSceneObjects));
    if (frames <= 0)
        throw InputError(name + ": Broadmark header: frame count " + std::to_string(frames) + " is not positive");
    if (u32_at(b, 264) != 0 || u32_at(b, 268) != 0)
        throw InputError(name + ": Broadmark header: the two padding integers are not 0");
    h.objects = std::uint32_t(n), h.frames = std::uint32_t(frames);
    h.world = box_at(b, 272, name + ": Broadmark header: world box");
    const std::uint64_t frame_bytes = std::uint64_t(n) * kBoxBytes;
    const std::uint64_t expected = kBroadmarkHeaderBytes + frame_bytes * (1 + std::uint64_t(h.frames));
    if (file_size != expected)
        throw InputError(name + ": " + std::to_string(file_size) + " bytes, but a header of " + std::to_string(n) +
                         " objects and " + std::to_string(frames) + " frames needs 304 + 32 x " + std::to_string(n) +
                         " x (1 + " + std::to_string(frames) + ") = " + std::to_string(expected) +
                         " (frame 0 and every counted frame)");
    return h;
}

/// The frames and objects a read takes: the limits, checked against the header and the memory
/// budget (kMaxRecordingBytes: every object once, and per frame every object moved plus the rays).
std::pair<std::uint32_t, std::uint32_t> taken(const Header& h, const BroadmarkLimits& limits, const std::string& name) {
    if (limits.frames && *limits.frames > h.frames)
        throw InputError(name + ": --frames " + std::to_string(*limits.frames) + ": the file has " +
                         std::to_string(h.frames) + " frames after frame 0");
    if (limits.objects > h.objects)
        throw InputError(name + ": --objects " + std::to_string(limits.objects) + ": the file has " +
                         std::to_string(h.objects) + " objects");
    const std::uint32_t frames = limits.frames.value_or(h.frames);
    const std::uint32_t objects = limits.objects ? limits.objects : h.objects;
    const double rays = limits.rays_per_frame, budget = double(kMaxRecordingBytes);
    const double bytes = recording_bytes(objects, frames, rays, objects);
    if (bytes > budget) {
        // The largest part that fits: frames at this object count, objects at this frame count.
        const double per_frame = recording_bytes(0, 1, rays, objects), all_rays = recording_bytes(0, frames, rays, 0);
        const auto max_frames = std::uint64_t(std::max(0.0, (budget - recording_bytes(objects, 0, 0, 0)) / per_frame));
        const auto max_objects = std::uint64_t(std::max(0.0, (budget - all_rays) / recording_bytes(1, frames, 0, 1)));
        char text[200];
        std::snprintf(text, sizeof text,
                      "%u objects and %u frames (every object moving, %u rays a frame) would take %.3g GB, over the "
                      "memory budget of %.3g GB; to stay under it take",
                      objects, frames, limits.rays_per_frame, bytes / 1e9, budget / 1e9);
        std::string how = " --frames " + std::to_string(max_frames) + " or fewer";
        if (max_objects >= 1) how += ", or --objects " + std::to_string(max_objects) + " or fewer";
        if (rays > 0) how += ", or fewer --rays";
        throw InputError(name + ": " + text + how);
    }
    return {frames, objects};
}

nlohmann::json point(const Vec3& p) { return {p.x, p.y, p.z}; }

/// The recording of a parsed file: `block(f, count)` gives the bytes of the first `count` boxes of
/// block f (0 = frame 0).
template <class Block>
Recording decode(const Header& h, const BroadmarkLimits& limits, const std::string& name, Block block) {
    const auto [frames, objects] = taken(h, limits, name);
    Recording r;
    nlohmann::json meta = {{"generator", "rcbench import"},
                           {"importer", "broadmark"},
                           {"source", std::filesystem::path(name).filename().string()},
                           {"objects", objects},
                           {"broadmark",
                            {{"scene_name", h.scene_name},
                             {"object_type", h.object_type},
                             {"objects", h.objects},
                             {"frames", h.frames},
                             {"world", {{"min", point(h.world.min)}, {"max", point(h.world.max)}}}}}};
    r.meta = meta.dump();
    std::vector<Aabb> current(objects);
    for (std::uint32_t f = 0; f <= frames; ++f) {
        const std::string bytes = block(f, objects);
        Frame frame;
        for (std::uint32_t i = 0; i < objects; ++i) {
            const Aabb box = box_at(bytes, std::size_t(i) * kBoxBytes,
                                    name + ": frame " + std::to_string(f) + ": object " + std::to_string(i));
            if (f == 0)
                r.initial.push_back({Uid(i), current[i] = box});
            else if (std::memcmp(&box, &current[i], sizeof box) != 0)
                frame.moves.push_back({Uid(i), current[i] = box});
        }
        if (f > 0) r.frames.push_back(std::move(frame));
    }
    return r;
}

}  // namespace

Recording decode_broadmark(const std::string& bytes, const std::string& name, const BroadmarkLimits& limits) {
    const Header h = parse_header(bytes, bytes.size(), name);
    const std::size_t block_bytes = std::size_t(h.objects) * kBoxBytes;
    return decode(h, limits, name, [&](std::uint32_t f, std::uint32_t count) {
        return bytes.substr(kBroadmarkHeaderBytes + std::size_t(f) * block_bytes, std::size_t(count) * kBoxBytes);
    });
}

Recording read_broadmark(const std::string& path, const BroadmarkLimits& limits) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path + ": cannot open");
    std::error_code ec;
    const std::uint64_t size = std::filesystem::file_size(path, ec);
    if (ec) throw InputError(path + ": cannot read its size");
    std::string header(std::min<std::uint64_t>(size, kBroadmarkHeaderBytes), '\0');
    in.read(header.data(), std::streamsize(header.size()));
    const Header h = parse_header(header, size, path);  // every size check before any box is read
    const std::uint64_t block_bytes = std::uint64_t(h.objects) * kBoxBytes;
    return decode(h, limits, path, [&](std::uint32_t f, std::uint32_t count) {
        std::string bytes(std::size_t(count) * kBoxBytes, '\0');
        in.seekg(std::streamoff(kBroadmarkHeaderBytes + std::uint64_t(f) * block_bytes));
        in.read(bytes.data(), std::streamsize(bytes.size()));
        if (std::uint64_t(in.gcount()) != bytes.size())
            throw InputError(path + ": could not read frame " + std::to_string(f));
        return bytes;
    });
}

namespace {

/// The meta's "broadmark" object (an imported file's header), or null.
nlohmann::json broadmark_meta(const Recording& r) {
    const nlohmann::json meta = nlohmann::json::parse(r.meta, nullptr, false);
    if (meta.is_object() && meta.contains("broadmark") && meta["broadmark"].is_object()) return meta["broadmark"];
    return nullptr;
}

/// A header string: what the meta says, else `fallback`, cut at a NUL and to 127 bytes, each
/// byte that is not printable written as '?' and an empty one as `fallback`, so Broadmark's
/// reader (Scene::ValidateString) accepts it.
void put_name(std::string& out, const nlohmann::json& bm, const char* key, const std::string& fallback) {
    std::string text = fallback;
    if (bm.is_object() && bm.contains(key) && bm[key].is_string()) text = bm[key].get<std::string>();
    text = text.substr(0, std::min(text.find('\0'), kNameBytes - 1));
    if (text.empty()) text = fallback;
    for (char& c : text)
        if (!std::isprint(static_cast<unsigned char>(c))) c = '?';
    out += text;
    out.append(kNameBytes - text.size(), '\0');
}

/// The meta's world box, when it has a valid one; else `world` is left as it was.
void world_from_meta(const nlohmann::json& bm, Aabb& world) {
    try {
        const auto& w = bm.at("world");
        Aabb given;
        for (int a = 0; a < 3; ++a) {
            given.min[a] = w.at("min").at(a).get<float>();
            given.max[a] = w.at("max").at(a).get<float>();
        }
        if (box_problem(given).empty()) world = given;
    } catch (const nlohmann::json::exception&) {
        // no world box in the meta: the bounds of the boxes stand
    }
}

}  // namespace

std::string encode_broadmark(const Recording& r, const std::string& name) {
    if (r.initial.empty()) throw InputError(name + ": no objects (a Broadmark file holds at least one)");
    if (r.frames.empty())
        throw InputError(name +
                         ": the recording has only frame 0; a Broadmark file needs at least one frame after "
                         "it (its reader requires frames > 0)");
    const nlohmann::json bm = broadmark_meta(r);
    const std::uint32_t blocks = std::uint32_t(r.frames.size() + 1);
    std::unordered_map<Uid, std::size_t> column;
    std::vector<Aabb> current;
    for (const Object& o : r.initial) column.emplace(o.uid, current.size()), current.push_back(o.box);
    Aabb world = bounds_of(r.initial);
    for (std::size_t f = 0; f < r.frames.size(); ++f) {
        if (!r.frames[f].inserts.empty() || !r.frames[f].removes.empty())
            throw InputError(name + ": frame " + std::to_string(f + 1) +
                             " inserts or removes objects, which a Broadmark file (N fixed objects) cannot hold");
        for (const Object& o : r.frames[f].moves) world = merge(world, o.box);
    }
    const std::uint32_t frames = blocks - 1;  // Broadmark counts the frames after the initial one
    if (bm.is_object()) world_from_meta(bm, world);
    std::string out;
    out.reserve(kBroadmarkHeaderBytes + std::size_t(blocks) * current.size() * kBoxBytes);
    nlohmann::json meta = nlohmann::json::parse(r.meta, nullptr, false);
    const std::string fallback = meta.is_object() ? meta.value("preset", meta.value("kind", "rcbench")) : "rcbench";
    put_name(out, bm, "scene_name", fallback);
    put_name(out, bm, "object_type", "rcbench objects");
    put_u32(out, std::uint32_t(current.size()));
    put_u32(out, frames);
    put_u32(out, 0), put_u32(out, 0);
    auto put_box = [&out](const Aabb& b) {
        for (float v : {b.min.x, b.min.y, b.min.z, 0.0f, b.max.x, b.max.y, b.max.z, 0.0f}) put_f32(out, v);
    };
    put_box(world);
    for (std::uint32_t f = 0; f < blocks; ++f) {
        if (f > 0)
            for (const Object& o : r.frames[f - 1].moves) current[column.at(o.uid)] = o.box;
        for (const Aabb& b : current) put_box(b);
    }
    return out;
}

void write_broadmark(const Recording& recording, const std::string& path) {
    write_file_atomically(path, encode_broadmark(recording, path));
}

}  // namespace rcb
