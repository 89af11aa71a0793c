#include "core/scene/recording_io.h"

#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <unordered_set>

#include "core/base/error.h"
#include "core/base/output_file.h"
#include "core/scene/recording_sections.h"

namespace rcb {
namespace {

constexpr char kMagic[8] = {'R', 'C', 'B', 'S', 'C', 'E', 'N', 'E'};
constexpr std::uint32_t kByteOrderMark = 0x01020304;
constexpr std::size_t kObjectBytes = 4 + 6 * 4;               // version 1; version 2 adds a kind byte, see object()
constexpr std::size_t kMinShapedObjectBytes = 4 + 1 + 4 * 4;  // version 2's smallest: a sphere
constexpr std::size_t kRayBytes = 6 * 4;
constexpr std::size_t kSectionHeaderBytes = 4 + 8 + 4;
constexpr std::size_t kFrameHeaderBytes = 5 * 4;

std::uint32_t crc32_of(const char* data, std::size_t n) {
    uLong crc = crc32(0L, Z_NULL, 0);
    // zlib takes uInt lengths; feed large payloads in pieces.
    while (n > 0) {
        uInt chunk = static_cast<uInt>(std::min<std::size_t>(n, 1u << 30));
        crc = crc32(crc, reinterpret_cast<const Bytef*>(data), chunk);
        data += chunk;
        n -= chunk;
    }
    return static_cast<std::uint32_t>(crc);
}

class Encoder {
public:
    void u32(std::uint32_t v) {
        for (int i = 0; i < 4; ++i) out_.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
    }
    void u64(std::uint64_t v) {
        for (int i = 0; i < 8; ++i) out_.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
    }
    void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
    void vec(const Vec3& v) { f32(v.x), f32(v.y), f32(v.z); }
    /// Version 1: uid, box. Version 2: uid, kind byte, then the box (kind 0) or the shape's floats.
    void object(const Object& o, std::uint32_t version) {
        u32(o.uid);
        if (version >= 2) out_.push_back(static_cast<char>(o.shape.kind));
        if (o.shape.kind == ShapeKind::box) {
            vec(o.box.min), vec(o.box.max);
        } else {
            for (int i = 0; i < shape_floats(o.shape.kind); ++i) f32(o.shape.v[i]);
        }
    }
    void u8(std::uint8_t v) { out_.push_back(static_cast<char>(v)); }
    void bytes(const std::string& s) { out_ += s; }

    /// Appends a section: tag, length, checksum, then the payload `body` wrote into its encoder.
    template <typename Body>
    void section(const char (&tag)[5], Body&& body) {
        Encoder payload;
        body(payload);
        out_.append(tag, 4);
        u64(payload.out_.size());
        u32(crc32_of(payload.out_.data(), payload.out_.size()));
        out_ += payload.out_;
    }
    std::string take() { return std::move(out_); }

private:
    std::string out_;
};

}  // namespace

namespace sections {

/// Bounds-checked little-endian reads; running past the end is a truncated file.
class Decoder {
public:
    Decoder(const char* data, std::size_t size, std::string context)
        : data_(data), size_(size), context_(std::move(context)) {}

    std::uint32_t u32() {
        need(4);
        std::uint32_t v = 0;
        for (int i = 0; i < 4; ++i) v |= std::uint32_t(std::uint8_t(data_[pos_ + i])) << (8 * i);
        pos_ += 4;
        return v;
    }
    std::uint64_t u64() {
        std::uint64_t lo = u32();
        std::uint64_t hi = u32();
        return lo | (hi << 32);
    }
    float f32() { return std::bit_cast<float>(u32()); }
    Vec3 vec() {
        Vec3 v;
        v.x = f32(), v.y = f32(), v.z = f32();
        return v;
    }
    /// See Encoder::object. A shaped object's box is its shape's bounds, once the shape is valid.
    Object object(std::uint32_t version) {
        Object o;
        o.uid = u32();
        if (version >= 2) {
            need(1);
            const auto kind = std::uint8_t(data_[pos_++]);
            if (kind >= kShapeKinds)
                throw InputError(context_ + ": uid " + std::to_string(o.uid) + ": unknown shape kind " +
                                 std::to_string(kind) + " (known: 0 box, 1 triangle, 2 obb, 3 sphere, 4 capsule)");
            o.shape.kind = ShapeKind(kind);
        }
        if (o.shape.kind == ShapeKind::box) {
            o.box.min = vec();
            o.box.max = vec();
            return o;
        }
        for (int i = 0; i < shape_floats(o.shape.kind); ++i) o.shape.v[i] = f32();
        if (std::string problem = shape_problem(o.shape, kMaxCoordinate); !problem.empty())
            throw InputError(context_ + ": uid " + std::to_string(o.uid) + ": " + problem);
        o.box = shape_bounds(o.shape);
        return o;
    }
    std::uint8_t u8() {
        need(1);
        return std::uint8_t(data_[pos_++]);
    }
    std::string bytes(std::size_t n) {
        need(n);
        std::string s(data_ + pos_, n);
        pos_ += n;
        return s;
    }
    std::size_t remaining() const { return size_ - pos_; }
    std::size_t position() const { return pos_; }
    void need(std::size_t n) const {
        if (size_ - pos_ < n)
            throw InputError(context_ + ": truncated (needs " + std::to_string(n) + " more bytes at offset " +
                             std::to_string(pos_) + ", has " + std::to_string(size_ - pos_) + ")");
    }

private:
    const char* data_;
    std::size_t size_;
    std::size_t pos_ = 0;
    std::string context_;
};

}  // namespace sections

namespace {

using sections::Decoder;

/// Version 3's byte per ray; a frame whose rays are all `all` keeps no kinds (Frame::kinds).
void read_kinds(Decoder& p, Frame& f) {
    f.kinds.resize(f.rays.size());
    for (QueryKind& k : f.kinds) k = QueryKind(p.u8());
    if (std::all_of(f.kinds.begin(), f.kinds.end(), [](QueryKind k) { return k == QueryKind::all; })) f.kinds.clear();
}

}  // namespace

std::string coordinate_problem(double v, std::string_view text) {
    if (!std::isfinite(v) && text.empty()) return "non-finite coordinate";
    const double a = std::abs(v);
    // The limits as floats hold: 1e-20 written in a file reads as the float just below 1e-20.
    if (a <= kMaxCoordinate && (a >= double(float(kMinCoordinate)) || a == 0)) return {};
    char value[32], limit[32];
    std::snprintf(value, sizeof value, "%g", v);
    std::snprintf(limit, sizeof limit, "%g", a > kMaxCoordinate ? kMaxCoordinate : kMinCoordinate);
    const std::string shown = text.empty() ? std::string(value) : quoted_excerpt(text);
    if (a > kMaxCoordinate)
        return "coordinate " + shown + " beyond ±" + limit + " (the largest magnitude every structure handles exactly)";
    return "coordinate " + shown + " below " + limit +
           " in magnitude (write 0: float arithmetic is not exact that small)";
}

std::string box_problem(const Aabb& box) {
    for (const Vec3& p : {box.min, box.max})
        for (int a = 0; a < 3; ++a)
            if (std::string problem = coordinate_problem(p[a]); !problem.empty()) return problem;
    static const char* axes = "xyz";
    for (int a = 0; a < 3; ++a)
        if (box.min[a] > box.max[a]) return std::string("min > max on axis ") + axes[a];
    return {};
}

std::string segment_problem(const Segment& s) {
    for (const Vec3& p : {s.p0, s.p1})
        for (int a = 0; a < 3; ++a)
            if (std::string problem = coordinate_problem(p[a]); !problem.empty()) return problem;
    return {};
}

void check_object(const Object& o, const std::string& context) {
    std::string problem;
    if (o.shape.kind != ShapeKind::box) {
        problem = shape_problem(o.shape, kMaxCoordinate);
        if (problem.empty() && !(o.box == shape_bounds(o.shape)))
            problem = "box is not its " + std::string(shape_name(o.shape.kind)) +
                      "'s bounds (make shaped objects with shaped_object)";
    }
    if (problem.empty()) problem = box_problem(o.box);
    if (!problem.empty()) throw InputError(context + ": uid " + std::to_string(o.uid) + ": " + problem);
}

namespace sections {

void refuse_missing_folder(const std::string& path) {
    std::error_code ec;
    const std::filesystem::path folder = std::filesystem::absolute(path, ec).parent_path();
    if (!std::filesystem::is_directory(folder, ec))
        throw InputError(path + ": cannot open for writing (no folder " + folder.string() + ")");
}

std::string frame_context(const std::string& name, std::size_t frame) {
    return name + ": frame " + std::to_string(frame);
}

/// Validates one frame's changes against the live uid set and applies them to it.
void refuse_invalid_frame(const Frame& f, std::unordered_set<Uid>& live, const std::string& context) {
    std::unordered_set<Uid> touched;
    auto once = [&](Uid uid) {
        if (!touched.insert(uid).second)
            throw InputError(context + ": uid " + std::to_string(uid) + " changes more than once in the frame");
    };
    for (Uid uid : f.removes) {
        once(uid);
        if (live.erase(uid) == 0) throw InputError(context + ": remove of unknown uid " + std::to_string(uid));
    }
    for (const Object& o : f.inserts) {
        once(o.uid);
        check_object(o, context);
        if (!live.insert(o.uid).second)
            throw InputError(context + ": insert of uid " + std::to_string(o.uid) + ", which is already live");
    }
    for (const Object& o : f.moves) {
        once(o.uid);
        check_object(o, context);
        if (live.count(o.uid) == 0) throw InputError(context + ": move of unknown uid " + std::to_string(o.uid));
    }
    for (std::size_t i = 0; i < f.rays.size(); ++i) {
        std::string problem = segment_problem(f.rays[i]);
        if (!problem.empty()) throw InputError(context + ": ray " + std::to_string(i) + ": " + problem);
    }
    if (!f.kinds.empty() && f.kinds.size() != f.rays.size())
        throw InputError(context + ": " + std::to_string(f.kinds.size()) + " query kinds for " +
                         std::to_string(f.rays.size()) + " rays");
    for (std::size_t i = 0; i < f.kinds.size(); ++i)
        if (std::uint8_t(f.kinds[i]) >= kQueryKinds)
            throw InputError(context + ": ray " + std::to_string(i) + ": unknown query kind " +
                             std::to_string(int(f.kinds[i])) + " (known: 0 all, 1 closest, 2 any)");
}

std::unordered_set<Uid> refuse_invalid_initial(const std::vector<Object>& objects, const std::string& name) {
    std::unordered_set<Uid> live;
    live.reserve(objects.size());
    std::string context = frame_context(name, 0);
    for (const Object& o : objects) {
        check_object(o, context);
        if (!live.insert(o.uid).second) throw InputError(context + ": duplicate uid " + std::to_string(o.uid));
    }
    return live;
}

namespace {

bool any_shaped(const std::vector<Object>& objects) {
    return std::any_of(objects.begin(), objects.end(), [](const Object& o) { return o.shape.kind != ShapeKind::box; });
}

}  // namespace

std::uint32_t objects_version(const std::vector<Object>& objects) { return any_shaped(objects) ? 2 : 1; }

std::uint32_t frame_version(const Frame& f) {
    if (std::any_of(f.kinds.begin(), f.kinds.end(), [](QueryKind k) { return k != QueryKind::all; })) return 3;
    return any_shaped(f.inserts) || any_shaped(f.moves) ? 2 : 1;
}

std::string header_bytes(std::uint32_t version) {
    Encoder e;
    e.bytes(std::string(kMagic, sizeof kMagic));
    e.u32(version);
    e.u32(kByteOrderMark);
    return e.take();
}

std::string meta_section(const std::string& meta) {
    Encoder e;
    e.section("META", [&](Encoder& p) { p.bytes(meta); });
    return e.take();
}

std::string objects_section(const std::vector<Object>& objects, std::uint32_t version) {
    Encoder e;
    e.section("OBJS", [&](Encoder& p) {
        p.u32(static_cast<std::uint32_t>(objects.size()));
        for (const Object& o : objects) p.object(o, version);
    });
    return e.take();
}

std::string frame_section(const Frame& f, std::size_t number, std::uint32_t version) {
    Encoder e;
    e.section("FRAM", [&](Encoder& p) {
        p.u32(static_cast<std::uint32_t>(number));
        p.u32(static_cast<std::uint32_t>(f.removes.size()));
        p.u32(static_cast<std::uint32_t>(f.inserts.size()));
        p.u32(static_cast<std::uint32_t>(f.moves.size()));
        p.u32(static_cast<std::uint32_t>(f.rays.size()));
        for (Uid uid : f.removes) p.u32(uid);
        for (const Object& o : f.inserts) p.object(o, version);
        for (const Object& o : f.moves) p.object(o, version);
        for (const Segment& s : f.rays) p.vec(s.p0), p.vec(s.p1);
        if (version >= 3)
            for (std::size_t ray = 0; ray < f.rays.size(); ++ray) p.u8(std::uint8_t(f.kind(ray)));
    });
    return e.take();
}

std::string end_section() {
    Encoder e;
    e.section("END ", [](Encoder&) {});
    return e.take();
}

std::string Reading::take(std::uint64_t n) {
    const std::uint64_t count = std::min(n, size - pos);
    std::string out(count, '\0');
    in->read(out.data(), static_cast<std::streamsize>(count));
    if (std::uint64_t(in->gcount()) != count)
        throw InputError(name + ": truncated (cannot read " + std::to_string(count) + " bytes at offset " +
                         std::to_string(pos) + ")");
    pos += count;
    return out;
}

void Reading::read_header() {
    const std::string head = take(sizeof kMagic + 8);
    Decoder header(head.data(), head.size(), name + ": header");
    if (head.size() < sizeof kMagic || std::memcmp(head.data(), kMagic, sizeof kMagic) != 0)
        throw InputError(name + ": not an rcbench scene recording (bad magic; expected \"RCBSCENE\")");
    header.bytes(sizeof kMagic);
    version = header.u32();
    std::uint32_t bom = header.u32();
    if (bom != kByteOrderMark) throw InputError(name + ": unknown byte-order mark (corrupt header)");
    if (version < 1 || version > kRecordingVersion)
        throw InputError(name + ": format version " + std::to_string(version) +
                         " is not supported (this rcbench reads versions 1 to " + std::to_string(kRecordingVersion) +
                         ")");
}

void Reading::read_objects(Decoder& p, const std::string& where) {
    std::uint32_t n = p.u32();
    const bool fits = version == 1 ? p.remaining() == std::uint64_t(n) * kObjectBytes
                                   : p.remaining() >= std::uint64_t(n) * kMinShapedObjectBytes;
    if (!fits) throw InputError(where + ": size does not match its count of " + std::to_string(n) + " objects");
    initial.resize(n);
    for (Object& o : initial) o = p.object(version);
    if (p.remaining() != 0)
        throw InputError(where + ": size does not match its count of " + std::to_string(n) + " objects");
    live = refuse_invalid_initial(initial, name);
}

void Reading::read_frame(Decoder& p, std::uint64_t length, const std::string& where, Frame& f) {
    std::uint32_t number = p.u32();
    if (number != frames_seen + 1)
        throw InputError(where + ": section carries frame number " + std::to_string(number) + " (out of order)");
    std::uint32_t n_rem = p.u32(), n_ins = p.u32(), n_mov = p.u32(), n_ray = p.u32();
    const std::uint64_t objects = std::uint64_t(n_ins) + n_mov,
                        fixed = kFrameHeaderBytes + std::uint64_t(n_rem) * 4 +
                                std::uint64_t(n_ray) * (kRayBytes + (version >= 3 ? 1 : 0));
    const bool fits =
        version == 1 ? length == fixed + objects * kObjectBytes : length >= fixed + objects * kMinShapedObjectBytes;
    if (!fits) throw InputError(where + ": size does not match its counts");
    f = Frame{};
    f.removes.resize(n_rem);
    for (Uid& uid : f.removes) uid = p.u32();
    f.inserts.resize(n_ins);
    for (Object& o : f.inserts) o = p.object(version);
    f.moves.resize(n_mov);
    for (Object& o : f.moves) o = p.object(version);
    f.rays.resize(n_ray);
    for (Segment& s : f.rays) s.p0 = p.vec(), s.p1 = p.vec();
    if (version >= 3) read_kinds(p, f);
    if (p.remaining() != 0) throw InputError(where + ": size does not match its counts");
    refuse_invalid_frame(f, live, where);
    ++frames_seen;
}

bool Reading::section(Frame* frame) {
    const std::uint64_t start = pos;
    if (start == size) {
        if (unterminated && expect == Expect::frames) {
            expect = Expect::done;
            return false;
        }
        throw InputError(name + ": truncated (file ends before the END section)");
    }
    const std::string head = take(kSectionHeaderBytes);
    Decoder sh(head.data(), head.size(), name + ": section header at offset " + std::to_string(start));
    std::string tag = sh.bytes(4);
    std::uint64_t length = sh.u64();
    std::uint32_t crc = sh.u32();
    // Errors name the frame for frame sections, else the section.
    std::string where =
        tag == "FRAM" ? frame_context(name, frames_seen + 1) : name + ": section " + quoted_excerpt(tag);
    if (length > size - pos)
        throw InputError(where + ": truncated (section of " + std::to_string(length) + " bytes, " +
                         std::to_string(size - pos) + " left in the file)");
    const std::string payload = take(length);
    if (crc32_of(payload.data(), length) != crc) throw InputError(where + ": checksum mismatch (corrupt file)");
    Decoder p(payload.data(), length, where);
    if (tag == "META") {
        if (expect != Expect::meta) throw InputError(where + ": unexpected META section");
        meta = p.bytes(length);
        expect = Expect::objs;
    } else if (tag == "OBJS") {
        if (expect != Expect::objs) throw InputError(where + ": unexpected OBJS section");
        read_objects(p, where);
        expect = Expect::frames;
    } else if (tag == "FRAM") {
        if (expect != Expect::frames) throw InputError(where + ": frame section before the objects");
        read_frame(p, length, where, *frame);
        return true;
    } else if (tag == "END ") {
        if (expect != Expect::frames) throw InputError(where + ": END before the objects");
        if (length != 0) throw InputError(where + ": END section is not empty");
        if (pos != size) throw InputError(name + ": " + std::to_string(size - pos) + " bytes after the END section");
        expect = Expect::done;
    } else {
        throw InputError(name + ": unknown section tag " + quoted_excerpt(tag) + " at offset " + std::to_string(start) +
                         " (corrupt file)");
    }
    return false;
}

void Reading::read_prologue() {
    read_header();
    while (expect != Expect::frames) section(nullptr);
}

std::unique_ptr<Reading> open_reading(const std::string& path, bool unterminated) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec)) throw InputError(path + ": is a directory, not a scene recording");
    auto reading = std::make_unique<Reading>();
    reading->file.open(path, std::ios::binary);
    if (!reading->file) throw InputError(path + ": cannot open (" + std::strerror(errno) + ")");
    reading->file.seekg(0, std::ios::end);
    reading->size = std::uint64_t(reading->file.tellg());
    reading->file.seekg(0);
    reading->in = &reading->file;
    reading->name = path;
    reading->unterminated = unterminated;
    return reading;
}

std::unique_ptr<Reading> memory_reading(const std::string& bytes, const std::string& name) {
    auto reading = std::make_unique<Reading>();
    reading->memory.str(bytes);
    reading->in = &reading->memory;
    reading->size = bytes.size();
    reading->name = name;
    return reading;
}

}  // namespace sections

void refuse_invalid_recording(const Recording& r, const std::string& name) {
    std::unordered_set<Uid> live = sections::refuse_invalid_initial(r.initial, name);
    for (std::size_t i = 0; i < r.frames.size(); ++i)
        sections::refuse_invalid_frame(r.frames[i], live, sections::frame_context(name, i + 1));
}

std::uint32_t recording_version(const Recording& r) {
    std::uint32_t version = sections::objects_version(r.initial);
    for (const Frame& f : r.frames) version = std::max(version, sections::frame_version(f));
    return version;
}

std::string encode_recording(const Recording& r) {
    const std::uint32_t version = recording_version(r);
    std::string out = sections::header_bytes(version) + sections::meta_section(r.meta) +
                      sections::objects_section(r.initial, version);
    for (std::size_t i = 0; i < r.frames.size(); ++i) out += sections::frame_section(r.frames[i], i + 1, version);
    return out + sections::end_section();
}

namespace {

/// Every frame of `reading` kept: the whole recording in memory.
Recording read_all(sections::Reading& reading) {
    reading.read_prologue();
    Recording r;
    r.meta = std::move(reading.meta);
    r.initial = std::move(reading.initial);
    for (Frame f; reading.section(&f);) r.frames.push_back(std::move(f));
    return r;
}

}  // namespace

Recording decode_recording(const std::string& bytes, const std::string& name) {
    return read_all(*sections::memory_reading(bytes, name));
}

Recording read_recording(const std::string& path) { return read_all(*sections::open_reading(path, false)); }

void write_recording(const Recording& r, const std::string& path) {
    refuse_invalid_recording(r, path + " (not written)");
    sections::refuse_missing_folder(path);
    // A hidden temporary file of a unique name beside `path`, renamed over it when complete: a
    // file of the user's, whatever its name, is never overwritten but `path` itself.
    write_file_atomically(path, encode_recording(r));
}

}  // namespace rcb
