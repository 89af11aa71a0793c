#include "core/scene/import/broadmark.h"

#include <bit>
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
    std::uint32_t objects = 0, frames = 0, blocks = 0;
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

/// The string of a 128-byte field: up to its NUL, which must come within the field.
std::string name_at(const std::string& b, std::size_t at, const std::string& where) {
    const void* nul = std::memchr(b.data() + at, 0, kNameBytes);
    if (!nul) throw InputError(where + ": no NUL within its 128 bytes (not a Broadmark scene file?)");
    return b.substr(at, static_cast<const char*>(nul) - (b.data() + at));
}

/// Parses and checks the header against the file's size: the data must be whole frames of N boxes,
/// as many as the header's frame count or one more (the initial frame besides the counted steps).
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
    const std::uint64_t frame_bytes = std::uint64_t(n) * kBoxBytes, data = file_size - kBroadmarkHeaderBytes;
    const std::uint64_t blocks = data / frame_bytes;
    if (data % frame_bytes != 0 || (blocks != h.frames && blocks != std::uint64_t(h.frames) + 1))
        throw InputError(name + ": " + std::to_string(data) + " bytes after the header are not " +
                         std::to_string(h.frames) + " or " + std::to_string(h.frames + 1ull) + " frames of " +
                         std::to_string(n) + " boxes (" + std::to_string(frame_bytes) + " bytes each)");
    h.blocks = std::uint32_t(blocks);
    check_scene_size(n, double(blocks) - 1, 0, n, name);
    return h;
}

nlohmann::json point(const Vec3& p) { return {p.x, p.y, p.z}; }

}  // namespace

Recording decode_broadmark(const std::string& bytes, const std::string& name) {
    const Header h = parse_header(bytes, bytes.size(), name);
    Recording r;
    nlohmann::json meta = {{"generator", "rcbench import"},
                           {"importer", "broadmark"},
                           {"source", std::filesystem::path(name).filename().string()},
                           {"objects", h.objects},
                           {"broadmark",
                            {{"scene_name", h.scene_name},
                             {"object_type", h.object_type},
                             {"frames", h.frames},
                             {"world", {{"min", point(h.world.min)}, {"max", point(h.world.max)}}}}}};
    r.meta = meta.dump();
    std::size_t at = kBroadmarkHeaderBytes;
    std::vector<Aabb> current(h.objects);
    for (std::uint32_t i = 0; i < h.objects; ++i, at += kBoxBytes) {
        current[i] = box_at(bytes, at, name + ": frame 0: object " + std::to_string(i));
        r.initial.push_back({Uid(i), current[i]});
    }
    for (std::uint32_t f = 1; f < h.blocks; ++f) {
        Frame frame;
        for (std::uint32_t i = 0; i < h.objects; ++i, at += kBoxBytes) {
            const Aabb box = box_at(bytes, at, name + ": frame " + std::to_string(f) + ": object " + std::to_string(i));
            if (std::memcmp(&box, &current[i], sizeof box) != 0) frame.moves.push_back({Uid(i), current[i] = box});
        }
        r.frames.push_back(std::move(frame));
    }
    return r;
}

Recording read_broadmark(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path + ": cannot open");
    std::error_code ec;
    const std::uint64_t size = std::filesystem::file_size(path, ec);
    if (ec) throw InputError(path + ": cannot read its size");
    std::string header(std::min<std::uint64_t>(size, kBroadmarkHeaderBytes), '\0');
    in.read(header.data(), std::streamsize(header.size()));
    parse_header(header, size, path);  // every size check before the whole file is read
    std::string bytes = header;
    bytes.resize(size);
    in.read(bytes.data() + header.size(), std::streamsize(size - header.size()));
    if (std::uint64_t(in.gcount()) != size - header.size()) throw InputError(path + ": could not read the whole file");
    return decode_broadmark(bytes, path);
}

namespace {

/// The meta's "broadmark" object (an imported file's header), or null.
nlohmann::json broadmark_meta(const Recording& r) {
    const nlohmann::json meta = nlohmann::json::parse(r.meta, nullptr, false);
    if (meta.is_object() && meta.contains("broadmark") && meta["broadmark"].is_object()) return meta["broadmark"];
    return nullptr;
}

/// A header string: what the meta says, else `fallback`, cut at a NUL and to 127 bytes.
void put_name(std::string& out, const nlohmann::json& bm, const char* key, std::string text) {
    if (bm.is_object() && bm.contains(key) && bm[key].is_string()) text = bm[key].get<std::string>();
    text = text.substr(0, std::min(text.find('\0'), kNameBytes - 1));
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
    std::uint32_t frames = blocks;
    if (bm.is_object() && bm.contains("frames") && bm["frames"].is_number_unsigned()) {
        const auto given = bm["frames"].get<std::uint64_t>();
        if (given == blocks || given + 1 == blocks) frames = std::uint32_t(given);
    }
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
