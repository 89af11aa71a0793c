// Hostile input, end to end: every rcbench command is fed seeded mutations of valid inputs (a
// recording from `scene gen`, boxes and rays CSV, OBJ and glTF models, a Quake III BSP, experiment
// and tuning files, a tuner's results, a results database made by `run`) and hostile arguments.
// Every case must end with exit 0 or 2 (never a signal, never 1: each input here is either valid
// or bad input), on exit 2 with exactly one line on stderr naming the file or option; within the
// time limit (a stalled command is killed); without changing any file it was not asked to write
// (size, mtime and content) and without leaving stray files beside its outputs.
//
// Failures are gathered per command and kind, and reported with the exact command line. The
// mutations are deterministic (rcb::Random with fixed seeds): the same build runs the same cases.
// RCB_HOSTILE_KEEP=1 keeps the work folders (a failing case's input stays there, next to
// failures.txt listing every failing case); RCB_HOSTILE_SCALE multiplies the number of mutants
// (default 1, 0.25 in sanitizer builds, which run several times slower).
#include <gtest/gtest.h>

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "core/base/random.h"
#include "core/scene/recording_io.h"
#include "core/scene/shape.h"
#include "runner/sqlite.h"
#include "tests/subprocess.h"

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(undefined_behavior_sanitizer)
#define RCB_HOSTILE_SANITIZED 1
#endif
#endif
#if defined(RCB_TESTS_SANITIZED) || defined(__SANITIZE_ADDRESS__)
#define RCB_HOSTILE_SANITIZED 1
#endif

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

#ifdef RCB_HOSTILE_SANITIZED
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

double mutant_scale() {
    if (const char* s = std::getenv("RCB_HOSTILE_SCALE")) return std::max(0.0, std::atof(s));
    return kSanitized ? 0.25 : 1.0;
}
/// How many mutants of a kind to run: n at scale 1, at least one.
int mutants(int n) { return std::max(1, int(std::lround(n * mutant_scale()))); }
/// A case using more CPU time than this stalled (the sanitizers slow rcbench down several times).
/// CPU time: a process beside it on the core does not bring the limit closer, as it would a wall
/// time (a niced suite beside two busy processes waits many times its work). About twice the
/// slowest case that does its work on the slowest machine it has run on: a whole run of the tiny
/// experiment, most of it the run's calibration pass (every structure on the micro-scenes).
double time_limit() { return kSanitized ? 75.0 : 25.0; }
/// A case still running after this much wall time stalled too: one that waits without working.
double wall_limit() { return 10 * time_limit(); }

std::string read_bytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}
void write_bytes(const fs::path& p, const std::string& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

std::uint64_t fnv1a(const std::string& bytes) {
    std::uint64_t h = 0xcbf29ce484222325ULL;
    for (unsigned char c : bytes) h = (h ^ c) * 0x100000001b3ULL;
    return h;
}

// ---------------------------------------------------------------------------------------------
// Mutations. Each returns the mutated bytes and says what it did (for the report).

struct Mutant {
    std::string bytes;
    std::string what;
    std::vector<std::string> places;  // further names an error may give instead of the file's (e.g. a path it holds)
};

std::string pick(rcb::Random& r, const std::vector<std::string>& list) { return list[r.below(list.size())]; }

/// Numbers at and beyond the edges of what the fields hold (float and double range, integer
/// widths, negative zero, denormals) and number-like tokens that are not JSON numbers.
const std::vector<std::string> kExtremeNumbers = {"1e999",
                                                  "-1e999",
                                                  "1e308",
                                                  "-1e308",
                                                  "1.7976931348623157e308",
                                                  "-0",
                                                  "-0.0",
                                                  "0",
                                                  "nan",
                                                  "NaN",
                                                  "-nan",
                                                  "inf",
                                                  "-inf",
                                                  "Infinity",
                                                  "-Infinity",
                                                  "1e20",
                                                  "-1e20",
                                                  "3e38",
                                                  "3.4028235e38",
                                                  "3.5e38",
                                                  "-3.5e38",
                                                  "1e-320",
                                                  "5e-324",
                                                  "1e-46",
                                                  "18446744073709551616",
                                                  "18446744073709551615",
                                                  "9223372036854775808",
                                                  "9223372036854775807",
                                                  "-9223372036854775809",
                                                  "-1",
                                                  "4294967296",
                                                  "4294967295",
                                                  "2147483648",
                                                  "-2147483649",
                                                  "0.5",
                                                  "1.5",
                                                  "0x10",
                                                  "1e",
                                                  "--1",
                                                  ".5",
                                                  "+1",
                                                  "01"};

/// Values of the wrong type, and ranges that are malformed, empty, endless or absurdly long.
const std::vector<std::string> kWrongTypes = {"true",
                                              "false",
                                              "null",
                                              R"("")",
                                              R"("x")",
                                              R"("1")",
                                              "[]",
                                              "{}",
                                              "[1]",
                                              "[[]]",
                                              "[null]",
                                              R"({"": 1})",
                                              R"({"from": true})",
                                              R"({"from": 1})",
                                              R"({"from": 1, "to": true, "step": 1})",
                                              R"({"from": 1, "to": 0, "step": 1})",
                                              R"({"from": 0, "to": 1e9, "step": 1e-9})",
                                              R"({"from": 1, "to": 1e308, "times": 1.0000001})",
                                              R"({"from": 1, "to": 8, "times": 1})",
                                              R"({"from": 1, "to": 8, "times": 0.5})",
                                              R"({"from": 1, "to": 8, "times": -2})",
                                              R"({"from": -1e308, "to": 1e308, "step": 1e-308})",
                                              R"({"from": 1, "to": 2, "step": 0})",
                                              R"({"from": 1, "to": 2, "step": 1, "times": 2})",
                                              R"({"from": 2, "to": 8, "step": -1})",
                                              R"({"from": 0, "to": 8, "times": 2})"};

/// Strings a path, name or mode field should survive: special files, escapes from the folder,
/// line breaks and control characters (which would split a one-line error), format directives.
const std::vector<std::string> kHostileStrings = {"",
                                                  " ",
                                                  ".",
                                                  "..",
                                                  "/",
                                                  "/dev/zero",
                                                  "/dev/stdin",
                                                  "/proc/self/mem",
                                                  "/proc/self",
                                                  "../../../../../../etc/passwd",
                                                  "../escape",
                                                  "a/b/c",
                                                  "a\nb",
                                                  "a\rb",
                                                  "\x1b[31mred",
                                                  "tab\there",
                                                  "%s%s%n",
                                                  "x\x01y",
                                                  "quote\"d",
                                                  "back\\slash",
                                                  "uni-s ",
                                                  "UNI-S",
                                                  "\xc3\xa9t\xc3\xa9",
                                                  "center:nan",
                                                  "center:-1",
                                                  "center:1e999",
                                                  "center:0",
                                                  ":",
                                                  ",",
                                                  "center:1,center:1"};

std::string nested(std::size_t depth, bool objects, bool closed) {
    std::string s;
    s.reserve(depth * 6 + 2);
    for (std::size_t i = 0; i < depth; ++i) s += objects ? "{\"a\":" : "[";
    if (!closed) return s;
    s += "1";
    for (std::size_t i = 0; i < depth; ++i) s += objects ? '}' : ']';
    return s;
}

/// 50 000 levels of nesting, 5 MB strings and numbers, invalid UTF-8: raw JSON text.
std::string raw_monster(rcb::Random& r, std::string& what) {
    switch (r.below(9)) {
        case 0:
            what = "50000 nested arrays";
            return nested(50000, false, true);
        case 1:
            what = "50000 unclosed [";
            return nested(50000, false, false);
        case 2:
            what = "50000 nested objects";
            return nested(50000, true, true);
        case 3:
            what = "5 MB string";
            return "\"" + std::string(5'000'000, 'a') + "\"";
        case 4:
            what = "5 MB of digits";
            return std::string(5'000'000, '9');
        case 5:
            what = "0. and 5 MB of zeros";
            return "0." + std::string(5'000'000, '0') + "1";
        case 6:
            what = "invalid UTF-8 string";
            return "\"ab\xff\xfe\xc0\xaf\xed\xa0\x80"
                   "cd\"";
        case 7:
            what = "string with NUL escape";
            return R"("a\u0000b")";
        default:
            what = "unterminated string";
            return "\"abc";
    }
}

/// Byte-level damage to any file.
Mutant mutate_bytes(const std::string& in, rcb::Random& r) {
    std::string s = in;
    const auto at = [&](std::size_t extra = 0) { return std::size_t(r.below(s.size() + extra)); };
    switch (s.empty() ? 9 : r.below(11)) {
        case 0: {
            const int n = 1 + int(r.below(4));
            std::string what = "flip bits at";
            for (int i = 0; i < n; ++i) {
                const std::size_t p = at();
                s[p] = char(s[p] ^ (1 << r.below(8)));
                what += " " + std::to_string(p);
            }
            return {s, what, {}};
        }
        case 1: {
            static const char interesting[] = {'\0', '\xff', '\x7f', '\x80', ' ', '9', '-',
                                               '.',  'e',    '"',    '[',    '{', ',', '\n'};
            const std::size_t p = at();
            s[p] = interesting[r.below(sizeof interesting)];
            return {s, "byte " + std::to_string(p) + " set to " + std::to_string(int((unsigned char)s[p])), {}};
        }
        case 2: {
            const std::size_t n = at();
            return {s.substr(0, n), "truncated to " + std::to_string(n) + " bytes", {}};
        }
        case 3: {
            const std::size_t p = at(), n = std::min<std::size_t>(1 + r.below(64), s.size() - p);
            s.erase(p, n);
            return {s, "deleted " + std::to_string(n) + " bytes at " + std::to_string(p), {}};
        }
        case 4: {
            const std::size_t p = at(), n = std::min<std::size_t>(1 + r.below(64), s.size() - p), q = at(1);
            s.insert(q, s.substr(p, n));
            return {
                s, "copied " + std::to_string(n) + " bytes from " + std::to_string(p) + " to " + std::to_string(q), {}};
        }
        case 5: {
            static const std::vector<std::string> bad = {"\xff\xfe", "\xc0\xaf", "\xed\xa0\x80", "\x80",
                                                         "\xf8\x88\x80\x80\x80"};
            const std::size_t p = at(1);
            s.insert(p, pick(r, bad));
            return {s, "invalid UTF-8 at " + std::to_string(p), {}};
        }
        case 6:
            return {"\xef\xbb\xbf" + s, "UTF-8 byte-order mark", {}};
        case 7: {
            const std::size_t p = at(1);
            s.insert(p, 1, '\0');
            return {s, "NUL byte at " + std::to_string(p), {}};
        }
        case 8: {
            std::string tail(1 + r.below(4096), '\0');
            for (char& c : tail) c = char(r.below(256));
            return {s + tail, "appended " + std::to_string(tail.size()) + " random bytes", {}};
        }
        case 9:
            return {"", "empty file", {}};
        default: {
            const std::size_t p = at(1);
            s.insert(p, std::string(5'000'000, 'A'));
            return {s, "5 MB inserted at " + std::to_string(p), {}};
        }
    }
}

void collect_pointers(const json& j, const json::json_pointer& p, std::vector<json::json_pointer>& out) {
    out.push_back(p);
    if (j.is_object())
        for (auto it = j.begin(); it != j.end(); ++it) collect_pointers(*it, p / it.key(), out);
    else if (j.is_array())
        for (std::size_t i = 0; i < j.size(); ++i) collect_pointers(j[i], p / i, out);
}

/// A structural mutation of a JSON document at a random node: an extreme number, a wrong type, a
/// hostile string, a monster (deep nesting, 5 MB), a removed, duplicated or unknown field; now and
/// then byte-level damage to the whole text instead.
Mutant mutate_json(const json& doc, rcb::Random& r) {
    if (r.below(5) == 0) return mutate_bytes(doc.dump(2), r);
    std::vector<json::json_pointer> nodes;
    collect_pointers(doc, json::json_pointer(), nodes);
    const json::json_pointer p = nodes[r.below(nodes.size())];
    json d = doc;
    const std::string where = p.empty() ? "(root)" : p.to_string();
    const std::string marker = "\x01RAW\x01";
    std::string raw, what;
    std::vector<std::string> places;
    const std::uint64_t op = r.below(100);
    if (op < 30) {
        raw = pick(r, kExtremeNumbers);
        what = where + " = " + raw;
    } else if (op < 52) {
        raw = pick(r, kWrongTypes);
        what = where + " = " + raw;
    } else if (op < 64) {
        const std::string s = pick(r, kHostileStrings);
        d[p] = s;
        what = where + " = " + json(s).dump(-1, ' ', false, json::error_handler_t::replace);
        if (!s.empty() && s.find_first_of("\n\r") == std::string::npos) places.push_back(s);
    } else if (op < 74) {
        raw = raw_monster(r, what);
        what = where + " = " + what;
    } else if (op < 84 && !p.empty()) {
        const json::json_pointer parent = p.parent_pointer();
        if (d[parent].is_object())
            d[parent].erase(p.back());
        else
            d[parent].erase(std::stoul(p.back()));
        what = where + " removed";
    } else if (op < 92 && !p.empty() && d[p.parent_pointer()].is_object()) {
        const std::string alt = r.below(2) ? pick(r, kExtremeNumbers) : pick(r, kWrongTypes);
        raw = d[p].dump() + ", " + json(p.back()).dump() + ": " + alt;
        what = where + " duplicated with " + alt;
    } else if (d[p].is_object()) {
        d[p]["zz_unknown"] = 1;
        what = where + ".zz_unknown = 1 added";
    } else {
        raw = pick(r, kExtremeNumbers);
        what = where + " = " + raw;
    }
    if (!raw.empty()) d[p] = marker;
    std::string text = d.dump(2);
    if (!raw.empty()) {
        const std::string quoted = json(marker).dump();
        text.replace(text.find(quoted), quoted.size(), raw);
    }
    return {text, what, places};
}

/// Damage to a CSV file of numbers: extreme and malformed fields, duplicated and missing lines
/// and columns, line endings, a byte-order mark, a 5 MB line.
Mutant mutate_csv(const std::string& text, rcb::Random& r) {
    std::vector<std::string> lines;
    for (std::size_t at = 0; at < text.size();) {
        const std::size_t nl = text.find('\n', at);
        lines.push_back(text.substr(at, nl - at));
        at = nl == std::string::npos ? text.size() : nl + 1;
    }
    auto join = [&](const std::string& eol = "\n") {
        std::string s;
        for (const std::string& l : lines) s += l + eol;
        return s;
    };
    const std::size_t li = r.below(lines.size());
    switch (r.below(12)) {
        case 0:
        case 1:
        case 2:
        case 3: {
            std::vector<std::string> fields;
            std::size_t at = 0;
            for (std::size_t c; (c = lines[li].find(',', at)) != std::string::npos; at = c + 1)
                fields.push_back(lines[li].substr(at, c - at));
            fields.push_back(lines[li].substr(at));
            const std::size_t fi = r.below(fields.size());
            static const std::vector<std::string> extra = {"",
                                                           " ",
                                                           " 1",
                                                           "1 ",
                                                           "\"1\"",
                                                           "1,2",
                                                           "1e",
                                                           "0x1p3",
                                                           "1e3",
                                                           "-",
                                                           "\t",
                                                           "1\r",
                                                           "\xff",
                                                           "\xef\xbb\xbf"
                                                           "1"};
            fields[fi] = r.below(3) ? pick(r, kExtremeNumbers) : pick(r, extra);
            std::string l;
            for (std::size_t i = 0; i < fields.size(); ++i) l += (i ? "," : "") + fields[i];
            lines[li] = l;
            return {join(),
                    "line " + std::to_string(li + 1) + " field " + std::to_string(fi + 1) + " = " +
                        json(fields[fi]).dump(-1, ' ', false, json::error_handler_t::replace),
                    {}};
        }
        case 4:
            lines.insert(lines.begin() + std::ptrdiff_t(li), lines[li]);
            return {join(), "line " + std::to_string(li + 1) + " duplicated", {}};
        case 5:
            lines.erase(lines.begin() + std::ptrdiff_t(li));
            return {join(), "line " + std::to_string(li + 1) + " removed", {}};
        case 6:
            lines[li] += ",1";
            return {join(), "line " + std::to_string(li + 1) + " has an extra column", {}};
        case 7: {
            const std::size_t c = lines[li].rfind(',');
            if (c != std::string::npos) lines[li].erase(c);
            return {join(), "line " + std::to_string(li + 1) + " lacks its last column", {}};
        }
        case 8:
            return {join("\r\n"), "CRLF line ends", {}};
        case 9: {
            static const std::vector<std::string> junk = {"", "   ", "# comment", ",,,,,,", "\r", std::string(1, '\0')};
            lines.insert(lines.begin() + std::ptrdiff_t(li), pick(r, junk));
            return {join(), "junk line before line " + std::to_string(li + 1), {}};
        }
        case 10:
            lines[li] += std::string(5'000'000, '1');
            return {join(), "5 MB line " + std::to_string(li + 1), {}};
        default:
            return mutate_bytes(text, r);
    }
}

/// Damage to an OBJ model: extreme and malformed numbers, faces out of range, hostile statements.
Mutant mutate_obj(const std::string& text, rcb::Random& r) {
    if (r.below(4) == 0) return mutate_bytes(text, r);
    static const std::vector<std::string> statements = {
        "mtllib /dev/zero",
        "mtllib ../../../../../../etc/passwd",
        "mtllib missing.mtl",
        "usemtl " + std::string(100000, 'm'),
        "f 1 2 99999999",
        "f 0 0 0",
        "f -99 -98 -97",
        "f 1",
        "f 1 2",
        "f 1/99999/1 2 3",
        "v 1e39 0 0",
        "v nan nan nan",
        "v inf -inf 0",
        "v 3e38 3e38 3e38\nv -3e38 -3e38 -3e38\nv 3e38 -3e38 0\nf -1 -2 -3",
        "vt 1e999 0",
        "vn nan 0 0",
        "l 1 2",
        "p 1",
        "o " + std::string(5'000'000, 'o'),
        "g",
        "s off",
        "v",
        "f",
        "curv 0 1 1 2",
        "#" + std::string(5'000'000, '#')};
    std::string s = text;
    if (r.below(2)) {
        const std::string st = pick(r, statements);
        const std::size_t nl = s.find('\n', r.below(s.size()));
        s.insert(nl == std::string::npos ? s.size() : nl + 1, st + "\n");
        return {
            s,
            "statement " + json(st.substr(0, 60)).dump(-1, ' ', false, json::error_handler_t::replace) + " inserted",
            {}};
    }
    // a number token replaced
    std::vector<std::size_t> starts;
    for (std::size_t i = 0; i < s.size(); ++i)
        if ((std::isdigit((unsigned char)s[i]) || s[i] == '-') && (i == 0 || s[i - 1] == ' ')) starts.push_back(i);
    const std::size_t st = starts[r.below(starts.size())];
    const std::size_t end = s.find_first_of(" \n", st);
    const std::string v = pick(r, kExtremeNumbers);
    s.replace(st, end - st, v);
    return {s, "number at " + std::to_string(st) + " = " + v, {}};
}

/// Damage to a binary file of 4-byte fields (a BSP: a lump directory of offsets and lengths, then
/// ints and floats): a word set to an extreme integer or float, or byte-level damage.
Mutant mutate_words(const std::string& in, rcb::Random& r) {
    if (r.below(3) == 0 || in.size() < 8) return mutate_bytes(in, r);
    static const std::uint32_t words[] = {0xffffffffu,
                                          0x7fffffffu,
                                          0x80000000u,
                                          0u,
                                          1u,
                                          0x7f800000u /* inf */,
                                          0x7fc00000u /* nan */,
                                          0xff800000u,
                                          0x7f7fffffu /* FLT_MAX */,
                                          0x00000001u /* denormal */,
                                          0x80000000u /* -0 */,
                                          0x10000000u,
                                          0xfffffff0u};
    std::string s = in;
    const int n = 1 + int(r.below(3));
    std::string what = "words";
    for (int i = 0; i < n; ++i) {
        const std::size_t p = 4 * r.below(s.size() / 4);
        const std::uint32_t w = words[r.below(std::size(words))];
        for (int b = 0; b < 4; ++b) s[p + b] = char((w >> (8 * b)) & 0xff);
        char hex[16];
        std::snprintf(hex, sizeof hex, "%08x", w);
        what += " @" + std::to_string(p) + "=" + hex;
    }
    return {s, what, {}};
}

// --- The recording format (core/scene/recording_io.h): sections after a 16-byte header. ---

struct Section {
    std::size_t at;  // offset of the tag
    std::string tag;
    std::uint64_t length;
};

std::vector<Section> sections(const std::string& b) {
    std::vector<Section> out;
    for (std::size_t at = 16; at + 16 <= b.size();) {
        std::uint64_t len = 0;
        for (int i = 7; i >= 0; --i) len = (len << 8) | (unsigned char)b[at + 4 + i];
        out.push_back({at, b.substr(at, 4), len});
        if (len > b.size() - at - 16) break;
        at += 16 + len;
    }
    return out;
}

void put_u32(std::string& b, std::size_t at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) b[at + i] = char((v >> (8 * i)) & 0xff);
}
void put_u64(std::string& b, std::size_t at, std::uint64_t v) {
    for (int i = 0; i < 8; ++i) b[at + i] = char((v >> (8 * i)) & 0xff);
}

/// Recomputes every section's CRC-32, so that the damage reaches the section parsers.
void fix_checksums(std::string& b) {
    for (const Section& s : sections(b)) {
        if (s.length > b.size() - s.at - 16) return;
        put_u32(b, s.at + 12,
                std::uint32_t(crc32(0, reinterpret_cast<const Bytef*>(b.data() + s.at + 16), uInt(s.length))));
    }
}

/// Damage to the recording's framing: header fields, section lengths, tags, counts, order.
Mutant mutate_framing(const std::string& in, rcb::Random& r) {
    std::string b = in;
    const std::vector<Section> secs = sections(b);
    const Section& s = secs[r.below(secs.size())];
    switch (r.below(10)) {
        case 0: {
            const std::uint32_t v = r.below(2) ? 0xffffffffu : std::uint32_t(r.below(4));
            put_u32(b, 8, v);
            return {b, "version " + std::to_string(v), {}};
        }
        case 1:
            put_u32(b, 12, 0x04030201u);
            return {b, "byte-order mark swapped", {}};
        case 2: {
            static const std::uint64_t lengths[] = {~0ULL, 1ULL << 63, 1ULL << 32, 0};
            const std::uint64_t len = lengths[r.below(std::size(lengths))];
            put_u64(b, s.at + 4, len);
            fix_checksums(b);
            return {b, s.tag + " section at " + std::to_string(s.at) + " length " + std::to_string(len), {}};
        }
        case 3: {
            static const char* tags[] = {"META", "OBJS", "FRAM", "END ", "XXXX", "\0\0\0\0"};
            b.replace(s.at, 4, tags[r.below(std::size(tags))], 4);
            return {b, s.tag + " section at " + std::to_string(s.at) + " retagged", {}};
        }
        case 4: {  // a count at the start of OBJS or FRAM
            if (s.length < 4) return mutate_bytes(in, r);
            const std::size_t field = s.tag == "FRAM" ? r.below(std::min<std::uint64_t>(5, s.length / 4)) : 0;
            static const std::uint32_t counts[] = {0xffffffffu, 0x7fffffffu, 0x10000000u, 0u, 2u};
            const std::uint32_t v = counts[r.below(std::size(counts))];
            put_u32(b, s.at + 16 + 4 * field, v);
            fix_checksums(b);
            return {b,
                    s.tag + " section at " + std::to_string(s.at) + " field " + std::to_string(field) + " = " +
                        std::to_string(v),
                    {}};
        }
        case 5: {  // a section repeated
            b.insert(s.at, b.substr(s.at, 16 + std::size_t(s.length)));
            return {b, s.tag + " section at " + std::to_string(s.at) + " repeated", {}};
        }
        case 6: {  // a section dropped
            b.erase(s.at, 16 + std::size_t(s.length));
            return {b, s.tag + " section at " + std::to_string(s.at) + " dropped", {}};
        }
        case 7: {  // two sections swapped
            const Section& t = secs[r.below(secs.size())];
            if (t.at <= s.at) return {b + b.substr(16), "sections repeated after END", {}};
            const std::string first = b.substr(s.at, 16 + s.length), second = b.substr(t.at, 16 + t.length);
            b.replace(t.at, second.size(), first);
            b.replace(s.at, first.size(), second);
            return {b, s.tag + " and " + t.tag + " sections swapped", {}};
        }
        case 8:
            return {b + "trailing", "bytes after END", {}};
        default: {
            Mutant m = mutate_bytes(in, r);
            fix_checksums(m.bytes);
            m.what += ", checksums fixed";
            return m;
        }
    }
}

/// Damage to the recording's content, encoded with correct framing: extreme, non-finite and
/// inverted coordinates, duplicate and dangling uids, hostile origin text; some of these are
/// valid scenes (huge but finite coordinates) that every structure must still cast exactly.
Mutant mutate_content(const rcb::Recording& base, rcb::Random& r) {
    rcb::Recording rec = base;
    static const float values[] = {std::numeric_limits<float>::quiet_NaN(),
                                   std::numeric_limits<float>::infinity(),
                                   -std::numeric_limits<float>::infinity(),
                                   -0.0f,
                                   3.4028235e38f,
                                   -3.4028235e38f,
                                   1e-45f,
                                   1e30f,
                                   -1e30f,
                                   0.0f,
                                   1.17549435e-38f,
                                   16777217.0f};
    const float v = values[r.below(std::size(values))];
    const int axis = int(r.below(3));
    auto some_frame = [&]() -> rcb::Frame& { return rec.frames[r.below(rec.frames.size())]; };
    char vtext[32];
    std::snprintf(vtext, sizeof vtext, "%g", double(v));
    switch (r.below(12)) {
        case 0: {
            rcb::Object& o = rec.initial[r.below(rec.initial.size())];
            (r.below(2) ? o.box.min : o.box.max)[axis] = v;
            return {rcb::encode_recording(rec), "uid " + std::to_string(o.uid) + " box coordinate = " + vtext, {}};
        }
        case 1: {
            rcb::Frame& f = some_frame();
            if (f.rays.empty()) return mutate_bytes(rcb::encode_recording(rec), r);
            rcb::Segment& s = f.rays[r.below(f.rays.size())];
            (r.below(2) ? s.p0 : s.p1)[axis] = v;
            return {rcb::encode_recording(rec), std::string("a ray coordinate = ") + vtext, {}};
        }
        case 2: {  // every coordinate scaled towards the float range's end: a valid, extreme scene
            const float k = r.below(2) ? 1e36f : 1e-36f;
            for (rcb::Object& o : rec.initial) o.box = {o.box.min * k, o.box.max * k};
            for (rcb::Frame& f : rec.frames) {
                for (rcb::Object& o : f.inserts) o.box = {o.box.min * k, o.box.max * k};
                for (rcb::Object& o : f.moves) o.box = {o.box.min * k, o.box.max * k};
                for (rcb::Segment& s : f.rays) s = {s.p0 * k, s.p1 * k};
            }
            return {rcb::encode_recording(rec),
                    std::string("every coordinate scaled by ") + (k > 1 ? "1e36" : "1e-36"),
                    {}};
        }
        case 3: {  // a box spanning the whole float range and a ray across it
            rec.initial[0].box = {{-3.4028235e38f, -3.4028235e38f, -3.4028235e38f},
                                  {3.4028235e38f, 3.4028235e38f, 3.4028235e38f}};
            if (!rec.frames.empty() && !rec.frames[0].rays.empty())
                rec.frames[0].rays[0] = {{-3.4028235e38f, 0, 0}, {3.4028235e38f, 1, 1}};
            return {rcb::encode_recording(rec), "a box and a ray spanning the float range", {}};
        }
        case 4: {
            rcb::Object& o = rec.initial[r.below(rec.initial.size())];
            std::swap(o.box.min[axis], o.box.max[axis]);
            o.box.max[axis] -= 1;
            return {rcb::encode_recording(rec), "uid " + std::to_string(o.uid) + " box inverted", {}};
        }
        case 5:
            rec.initial.push_back(rec.initial[r.below(rec.initial.size())]);
            return {rcb::encode_recording(rec), "duplicate uid in frame 0", {}};
        case 6:
            some_frame().removes.push_back(0xfffffff0u);
            return {rcb::encode_recording(rec), "remove of an unknown uid", {}};
        case 7:
            some_frame().inserts.push_back(rec.initial[0]);
            return {rcb::encode_recording(rec), "insert of a live uid", {}};
        case 8: {
            rcb::Frame& f = some_frame();
            f.removes.push_back(rec.initial[0].uid);
            f.moves.push_back(rec.initial[0]);
            return {rcb::encode_recording(rec), "the same uid removed and moved", {}};
        }
        case 9: {
            static const std::uint32_t uids[] = {0u, 0xffffffffu, 0x80000000u};
            rec.initial[r.below(rec.initial.size())].uid = uids[r.below(std::size(uids))];
            return {rcb::encode_recording(rec), "an extreme uid", {}};
        }
        case 10: {
            std::string what;
            rec.meta = raw_monster(r, what);
            return {rcb::encode_recording(rec), "origin text = " + what, {}};
        }
        default: {
            rec.initial.clear();
            for (rcb::Frame& f : rec.frames) f = {};
            return {rcb::encode_recording(rec), "no objects and empty frames", {}};
        }
    }
}

std::string base64(const std::string& in) {
    static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    for (std::size_t i = 0; i < in.size(); i += 3) {
        std::uint32_t v = std::uint32_t((unsigned char)in[i]) << 16;
        if (i + 1 < in.size()) v |= std::uint32_t((unsigned char)in[i + 1]) << 8;
        if (i + 2 < in.size()) v |= (unsigned char)in[i + 2];
        out += t[(v >> 18) & 63];
        out += t[(v >> 12) & 63];
        out += i + 1 < in.size() ? t[(v >> 6) & 63] : '=';
        out += i + 2 < in.size() ? t[v & 63] : '=';
    }
    return out;
}

// ---------------------------------------------------------------------------------------------
// Valid inputs.

const char* kBoxesCsv =
    "uid,minx,miny,minz,maxx,maxy,maxz\n"
    "10,0,0,0,1,1,1\n11,2,0,0,3,1,1\n12,0,5,0,1,6,1\n13,-4,-4,-4,-3.5,-3,-2\n14,0.5,0.5,0.5,0.5,0.5,0.5\n"
    "15,-10,0,0,10,0.25,0.25\n16,4,4,4,9,9,9\n17,1,1,1,2,2,2\n";
const char* kRaysCsv =
    "x0,y0,z0,x1,y1,z1\n-1,0.5,0.5,4,0.5,0.5\n0.5,-1,0.5,0.5,7,0.5\n9,9,9,9,9,9\n-20,0.1,0.1,20,0.1,0.1\n";
const char* kObj =
    "# two objects\no a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\n"
    "o b\nv 2 2 2\nv 3 2 2\nv 2 3 2\nv 2.5 2.5 3\nf 5 6 7\nf 5 6 8\n";

json gltf() {
    std::string buf;
    auto f32 = [&](float v) { buf.append(reinterpret_cast<const char*>(&v), 4); };
    for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f}) f32(v);
    for (std::uint16_t i : {0, 1, 2, 0, 1, 3}) buf.append(reinterpret_cast<const char*>(&i), 2);
    return {
        {"asset", {{"version", "2.0"}}},
        {"scene", 0},
        {"scenes", {{{"nodes", {0, 1}}}}},
        {"nodes",
         {{{"mesh", 0}, {"translation", {0, 0, 0}}}, {{"mesh", 0}, {"translation", {3, 0, 0}}, {"scale", {1, 2, 1}}}}},
        {"meshes", {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}, {"mode", 4}}}}}}},
        {"buffers", {{{"byteLength", buf.size()}, {"uri", "data:application/octet-stream;base64," + base64(buf)}}}},
        {"bufferViews",
         {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
          {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 12}}}},
        {"accessors",
         {{{"bufferView", 0},
           {"byteOffset", 0},
           {"componentType", 5126},
           {"count", 4},
           {"type", "VEC3"},
           {"min", {0, 0, 0}},
           {"max", {1, 1, 1}}},
          {{"bufferView", 1}, {"byteOffset", 0}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}}};
}

/// A tiny experiment touching every scene source and structure, with parameter ranges and grids.
json experiment() {
    return json::parse(R"({
  "name": "hostile", "description": "tiny", "frames": 2, "warmup_frames": 0, "rays_per_frame": 8,
  "ray_mix": "center:0.5,los:0.5", "seeds": [1], "repetitions": 1, "threads": 1, "verify": true,
  "scenes": [
    {"preset": "uni-s", "frames": 2},
    {"generator": "irregular", "objects": [30], "change_fraction": 0.1, "insert_share": 0.2, "remove_share": 0.2, "move_scale": 0.1, "seed": 3},
    {"recording": "base.rcbscene"},
    {"import": "boxes.csv", "frames": 2, "rays_per_frame": 8},
    {"import": "tiny.bsp", "frames": 1, "import_options": {"bsp_mode": "triangles"}}
  ],
  "structures": [
    {"name": "bf"}, {"name": "ug", "params": {"density": [1, 2]}},
    {"name": "hg", "params": {"max_depth": {"from": 1, "to": 2, "step": 1}, "amp": {"from": 0.5, "to": 1, "times": 2}}},
    {"name": "dbvh", "grids": [{"mode": "incremental"}, {"mode": "rebuild", "rebuild_every": [1]}]},
    {"name": "lbvh"}, {"name": "embree"}, {"name": "bullet_dbvt"}
  ]
})");
}

/// A tiny tuning file: both grids, one small category.
json tuning() {
    return json::parse(R"({
  "name": "hostile", "description": "tiny", "mode": "predicted-then-verified", "structures": ["ug", "hg"],
  "budget": 4, "calibration": 3, "verify_top": 1, "seed": 1, "frames": 2, "warmup_frames": 1, "rays_per_frame": 8,
  "ray_mix": "center", "repetitions": 1,
  "space": {"ug": {"density": {"from": 0.5, "to": 4, "times": 2}}, "hg": {"max_depth": [1, 2], "subdivision": [2, 3]}},
  "categories": [{"name": "tiny", "scenes": [{"preset": "uni-s", "frames": 2}, {"recording": "base.rcbscene"}]}]
})");
}

// ---------------------------------------------------------------------------------------------
// The harness.

struct Case {
    std::vector<std::string> args{};    // after the binary; relative paths are inside the work folder
    std::vector<std::string> places{};  // an exit-2 error must name one of these
    std::vector<std::string> writes{};  // what it was asked to write, relative ("dir/" for a folder's contents)
    std::vector<std::string> inputs{};  // files made for this case alone: removed after it unless it failed
    bool bad = false;                   // certainly bad input: exit 0 is a failure too
    std::string what{};                 // the mutation or hostile argument
};

struct Entry {
    bool dir = false;
    std::uintmax_t size = 0;
    fs::file_time_type mtime;
    std::uint64_t hash = 0;
};

class Hostile : public ::testing::Test {
protected:
    void SetUp() override {
        const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
        root_ = fs::temp_directory_path() / ("rcb_hostile_" + std::to_string(::getpid()) + "_" + name);
        fs::remove_all(root_);
        work_ = root_ / "work";
        fs::create_directories(work_);
    }

    void TearDown() override {
        report();
        if (std::getenv("RCB_HOSTILE_KEEP"))
            std::cout << "work folders kept in " << root_ << '\n';
        else
            fs::remove_all(root_);
    }

    // --- valid inputs, made on demand in the work folder ---

    /// Writes a base input; it is restored after any case that damaged it.
    void base(const std::string& name, const std::string& bytes) {
        write_bytes(work_ / name, bytes);
        bases_[name] = bytes;
    }

    /// Runs rcbench for a setup step (must succeed) and registers what it wrote as base inputs.
    void setup_run(const std::vector<std::string>& args, const std::vector<std::string>& outputs) {
        std::vector<std::string> argv{RCBENCH_BINARY};
        argv.insert(argv.end(), args.begin(), args.end());
        test::RunOptions o;
        o.cwd = work_.string();
        const test::Outcome r = test::run_process(argv, o);
        ASSERT_EQ(r.code, 0) << "setup: " << command_line(args) << '\n' << r.err;
        for (const std::string& out : outputs) {
            // A database's write-ahead log, if one was left beside it, is folded in first: the
            // base must be one self-contained file (closing the last writer checkpoints the log).
            if (fs::exists(work_ / (out + "-wal"))) rcb::Database((work_ / out).string(), false);
            bases_[out] = read_bytes(work_ / out);
        }
    }

    void make_recording() {
        setup_run({"scene", "gen", "--preset", "uni-s", "--frames", "3", "--rays", "16", "--ray-mix",
                   "center:0.4,los:0.2,ground:0.1,shots:0.1,faces:0.1,dense:0.1", "--change-fraction", "0.1", "--seed",
                   "7", "-o", "base.rcbscene"},
                  {"base.rcbscene"});
    }
    void make_csvs() {
        base("boxes.csv", kBoxesCsv);
        base("rays.csv", kRaysCsv);
    }
    void make_bsp() { base("tiny.bsp", read_bytes(fs::path(RCBENCH_SOURCE_DIR) / "tests/fuzz/seeds/bsp/tiny.bsp")); }
    void make_experiment() {
        make_recording();
        make_csvs();
        make_bsp();
        base("exp.json", experiment().dump(2));
    }
    /// r.db: two runs of a small experiment (so that compare has two), every structure.
    void make_database() {
        make_recording();
        json e = experiment();
        e["scenes"] = json::array({json{{"preset", "uni-s"}, {"frames", 2}}, json{{"recording", "base.rcbscene"}}});
        base("small.json", e.dump(2));
        setup_run({"run", "small.json", "--db", "r.db"}, {});
        setup_run({"run", "small.json", "--db", "r.db", "--new-run"}, {"r.db"});
    }
    void make_tuning_result() {
        make_recording();
        base("tune.json", tuning().dump(2));
        setup_run({"tune", "tune.json", "--db", "tune.db", "--out-dir", "tuned"}, {});
        base("tr.json", read_bytes(work_ / "tuned/tuning-hostile.json"));
        fs::remove_all(work_ / "tuned");
        for (const char* f : {"tune.db", "tune.db-wal", "tune.db-shm"}) fs::remove(work_ / f);
    }

    /// Removes a case's own input, unless a failing case keeps it for the report.
    void done(const std::string& name) {
        if (!kept_.count(name)) fs::remove(work_ / name);
    }

    /// A fresh name for a case's own file.
    std::string fresh(const std::string& stem, const std::string& ext) {
        return stem + "-" + std::to_string(++serial_) + ext;
    }
    std::string input(const std::string& stem, const std::string& ext, const std::string& bytes) {
        const std::string name = fresh(stem, ext);
        write_bytes(work_ / name, bytes);
        return name;
    }

    // --- running a case ---

    std::map<std::string, Entry> scan() const {
        std::map<std::string, Entry> s;
        std::error_code ec;
        for (auto it = fs::recursive_directory_iterator(work_, fs::directory_options::skip_permission_denied, ec);
             it != fs::recursive_directory_iterator(); it.increment(ec)) {
            if (ec) break;
            const std::string rel = fs::relative(it->path(), work_).string();
            if (kept_.count(rel)) continue;
            Entry e;
            const fs::file_status st = it->symlink_status();
            e.dir = fs::is_directory(st);
            if (fs::is_regular_file(st)) {
                e.size = it->file_size(ec);
                e.mtime = it->last_write_time(ec);
                e.hash = fnv1a(read_bytes(it->path()));
            }
            s[rel] = e;
        }
        return s;
    }

    static bool allowed(const std::string& path, const std::vector<std::string>& writes) {
        for (const std::string& w : writes) {
            if (path == w) return true;
            if (!w.empty() && w.back() == '/' && (path + "/" == w || path.rfind(w, 0) == 0)) return true;
            if (w.rfind(path + "/", 0) == 0) return true;  // a folder on the way to an output
        }
        return false;
    }

    /// The argument as bash takes it, on one line: control characters as $'\n' escapes, long
    /// runs of one character as a command substitution.
    static std::string shown(const std::string& arg) {
        if (arg.size() <= 200 &&
            std::none_of(arg.begin(), arg.end(), [](char c) { return (unsigned char)c < 0x20 || c == 0x7f; }))
            return test::shell_quote(arg);
        if (arg.size() <= 200) {
            std::string q = "$'";
            for (char c : arg) {
                const unsigned char u = (unsigned char)c;
                if (c == '\\' || c == '\'')
                    q += std::string("\\") + c;
                else if (u < 0x20 || u == 0x7f) {
                    char hex[8];
                    std::snprintf(hex, sizeof hex, "\\x%02x", u);
                    q += hex;
                } else
                    q += c;
            }
            return q + "'";
        }
        if (arg.find_first_not_of(arg[0]) == std::string::npos)
            return "\"$(head -c " + std::to_string(arg.size()) + " /dev/zero | tr '\\0' " +
                   test::shell_quote(std::string(1, arg[0])) + ")\"";
        return test::shell_quote(arg.substr(0, 60)) + "...(" + std::to_string(arg.size()) + " bytes)";
    }
    std::string command_line(const std::vector<std::string>& args) const {
        std::string s = "cd ";
        s += work_.string();
        s += " && ";
        s += RCBENCH_BINARY;
        for (const std::string& a : args) {
            s += ' ';
            s += shown(a);
        }
        return s;
    }

    /// Runs one case and records what went wrong with it under `group`.
    void check(const std::string& group, const Case& c) {
        const auto before = scan();
        std::vector<std::string> argv{RCBENCH_BINARY};
        argv.insert(argv.end(), c.args.begin(), c.args.end());
        test::RunOptions o;
        o.cwd = work_.string();
        o.cpu_seconds = time_limit();
        o.timeout_seconds = wall_limit();
        // Bounds a runaway allocation, so that it fails this case instead of the machine. ASan
        // reserves terabytes of address space and takes its limits as options instead.
        if (kSanitized) {
            const char* asan = std::getenv("ASAN_OPTIONS");
            o.env.push_back(std::string("ASAN_OPTIONS=") + (asan ? std::string(asan) + ":" : "") +
                            "hard_rss_limit_mb=6144:max_allocation_size_mb=6144");
        } else {
            o.address_space = std::uint64_t(16) << 30;
        }
        const test::Outcome r = test::run_process(argv, o);
        ++cases_;
        std::array<int, 3>& tally = outcomes_[group];
        ++tally[r.code == 0 ? 0 : r.code == 2 ? 1 : 2];

        std::vector<std::string> problems;
        const bool stalled = r.timed_out || r.cpu_limited;
        if (r.cpu_limited)
            problems.push_back("stalls (ended after " + std::to_string(int(time_limit())) + " s of CPU time)");
        else if (r.timed_out)
            problems.push_back("stalls (killed after " + std::to_string(int(wall_limit())) + " s of wall time)");
        else if (r.signal)
            problems.push_back("dies by signal " + std::to_string(r.signal) + " (" + strsignal(r.signal) + ")");
        else if (r.code == 1)
            problems.push_back("exits 1");
        else if (r.code != 0 && r.code != 2)
            problems.push_back("exits " + std::to_string(r.code));
        if (!stalled && r.code == 0 && c.bad) problems.push_back("accepts bad input (exit 0)");
        if (r.code == 2) {
            const bool one_line = !r.err.empty() && r.err.back() == '\n' &&
                                  std::count(r.err.begin(), r.err.end(), '\n') == 1 &&
                                  r.err.find('\r') == std::string::npos;
            if (!one_line) problems.push_back("error is not one line");
            bool named = c.places.empty();
            for (const std::string& p : c.places) named = named || r.err.find(p) != std::string::npos;
            if (!named) {
                std::string list;
                for (const std::string& p : c.places)
                    list += (list.empty() ? "" : " or ") +
                            json(p.substr(0, 60)).dump(-1, ' ', false, json::error_handler_t::replace);
                problems.push_back("error does not name " + list);
            }
        }
        const auto after = scan();
        bool damaged = false;
        for (const auto& [path, e] : before) {
            if (allowed(path, c.writes)) continue;
            const auto it = after.find(path);
            if (it == after.end()) {
                problems.push_back("removes " + path);
                damaged = true;
            } else if (!e.dir &&
                       (it->second.size != e.size || it->second.mtime != e.mtime || it->second.hash != e.hash)) {
                problems.push_back("changes " + path);
                damaged = true;
            }
        }
        if (!stalled)  // a killed process cannot clean up: the stall is its failure
            for (const auto& [path, e] : after)
                if (!before.count(path) && !allowed(path, c.writes)) problems.push_back("leaves stray " + path);

        // Back to the base state: outputs and strays removed, damaged base inputs restored.
        for (const auto& [path, e] : after)
            if (!before.count(path) && fs::exists(work_ / path)) fs::remove_all(work_ / path);
        for (const std::string& w : c.writes)
            if (!bases_.count(w)) fs::remove_all(work_ / w);
        for (const auto& [name, bytes] : bases_) {
            const auto it = after.find(name);
            if (damaged || it == after.end() || it->second.hash != fnv1a(bytes) || it->second.size != bytes.size())
                write_bytes(work_ / name, bytes);
        }

        if (problems.empty()) return;
        for (const std::string& f : c.inputs) kept_.insert(f);
        std::string outcome = stalled    ? "killed"
                              : r.signal ? "signal " + std::to_string(r.signal)
                                         : "exit " + std::to_string(r.code);
        // One line per case in the report: line breaks as '|', other control characters as '?'.
        auto flat = [](std::string t) {
            for (char& ch : t)
                if (ch == '\n')
                    ch = '|';
                else if ((unsigned char)ch < 0x20 || ch == 0x7f)
                    ch = '?';
            return t;
        };
        const std::string err = flat(r.err.substr(0, 300)), what = flat(c.what);
        std::string detail = command_line(c.args) + "\n      [" + what + "] " + outcome + ", " +
                             std::to_string(r.seconds).substr(0, 5) + " s, stderr: " + err;
        // One kind per problem ("changes x" and "changes y" are one kind: "changes").
        std::set<std::string> kinds;
        for (const std::string& p : problems) {
            const std::string kind = p.rfind("changes ", 0) == 0 || p.rfind("removes ", 0) == 0
                                         ? "changes or removes a file it was not asked to write"
                                     : p.rfind("leaves stray", 0) == 0        ? "leaves a stray file"
                                     : p.rfind("error does not name", 0) == 0 ? "error does not name the place"
                                                                              : p;
            kinds.insert(kind);
        }
        std::string all;
        for (const std::string& p : problems) all += (all.empty() ? "" : "; ") + p;
        for (const std::string& k : kinds) failures_[group + ": " + k].push_back(detail + "\n      problems: " + all);
        std::ofstream(root_ / "failures.txt", std::ios::app) << group << ": " << all << "\n    " << detail << "\n";
    }

    void report() {
        // How the cases ended, so that a suite whose mutants all fail early (or all pass) shows.
        for (const auto& [group, t] : outcomes_)
            std::cout << group << ": " << t[0] << " accepted, " << t[1] << " rejected, " << t[2] << " other\n";
        for (const auto& [kind, list] : failures_) {
            std::string text =
                kind + ": " + std::to_string(list.size()) + " of " + std::to_string(cases_) + " cases, e.g.\n";
            for (std::size_t i = 0; i < list.size() && i < 4; ++i) text += "    " + list[i] + "\n";
            ADD_FAILURE() << text;
        }
        if (!failures_.empty() && !std::getenv("RCB_HOSTILE_KEEP"))
            std::cout << "(RCB_HOSTILE_KEEP=1 keeps the failing inputs and the whole list in " << root_
                      << "/failures.txt)\n";
    }

    fs::path root_, work_;
    std::map<std::string, std::string> bases_;  // name -> pristine bytes
    std::set<std::string> kept_;                // failing cases' inputs, kept and no longer scanned
    std::map<std::string, std::vector<std::string>> failures_;
    std::map<std::string, std::array<int, 3>> outcomes_;  // per group: exit 0, exit 2, anything else
    int cases_ = 0;
    int serial_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Scene files.

/// `cast` takes one structure: the mutants take turns.
std::string structure(int i) {
    static const char* names[] = {"bf", "ug", "hg", "dbvh", "lbvh", "embree", "bullet_dbvt"};
    return names[i % 7];
}

// Over 30 s: 150 mutants, each through four or five rcbench processes (simulate: every structure).
TEST_F(Hostile, RecordingsForSceneInfoSimulateCastAdvise) {
    ASSERT_NO_FATAL_FAILURE(make_recording());
    ASSERT_NO_FATAL_FAILURE(make_csvs());
    const std::string good = bases_["base.rcbscene"];
    const rcb::Recording rec = rcb::decode_recording(good, "base.rcbscene");
    rcb::Random r(rcb::mix_seed(1, 1));
    const int n = mutants(150);
    for (int i = 0; i < n; ++i) {
        const Mutant m = i % 3 == 0   ? mutate_content(rec, r)
                         : i % 3 == 1 ? mutate_framing(good, r)
                                      : mutate_bytes(good, r);
        const std::string f = input("rec", ".rcbscene", m.bytes);
        std::vector<std::string> places = m.places;
        places.push_back(f);
        const std::string json_out = fresh("sim", ".json");
        check("scene info", {{"scene", "info", "--json", f}, places, {}, {f}, false, m.what});
        check("simulate", {{"simulate", "--scene", f, "--structure", "all", "--check", "--json-out", json_out},
                           places,
                           {json_out},
                           {f},
                           false,
                           m.what});
        check("cast", {{"cast", "--scene", f, "--rays", "rays.csv", "--structure", structure(i)},
                       places,
                       {},
                       {f},
                       false,
                       m.what});
        if (i % 8 == 0)
            check("advise", {{"advise", f, "--repetitions", "1", "--warmup", "0"}, places, {}, {f}, false, m.what});
        check("scene info", {{"scene", "info", f}, places, {}, {f}, false, m.what});
        done(f);
    }
}

// Over 30 s: 200 mutant CSV files, each through two or three rcbench processes.
TEST_F(Hostile, CsvForImportCastAdvise) {
    ASSERT_NO_FATAL_FAILURE(make_recording());
    ASSERT_NO_FATAL_FAILURE(make_csvs());
    rcb::Random r(rcb::mix_seed(1, 2));
    const int n = mutants(200);
    for (int i = 0; i < n; ++i) {
        const bool boxes = i % 3 != 2;
        const Mutant m = mutate_csv(boxes ? kBoxesCsv : kRaysCsv, r);
        const std::string f = input(boxes ? "boxes" : "rays", ".csv", m.bytes);
        std::vector<std::string> places = m.places;
        places.push_back(f);
        if (boxes) {
            const std::string out = fresh("imported", ".rcbscene");
            check(
                "scene import csv",
                {{"scene", "import", f, "--frames", "2", "--rays", "8", "-o", out}, places, {out}, {f}, false, m.what});
            check("cast", {{"cast", "--scene", f, "--rays", "rays.csv", "--structure", structure(i)},
                           places,
                           {},
                           {f},
                           false,
                           m.what});
            if (i % 10 == 0) check("advise", {{"advise", f, "--repetitions", "1"}, places, {}, {f}, false, m.what});
        } else {
            check("cast", {{"cast", "--scene", "base.rcbscene", "--rays", f, "--structure", structure(i)},
                           places,
                           {},
                           {f},
                           false,
                           m.what});
            check("cast", {{"cast", "--scene", "boxes.csv", "--rays", f, "--structure", structure(i + 3)},
                           places,
                           {},
                           {f},
                           false,
                           m.what});
        }
        done(f);
    }
}

// Over 30 s: 160 mutant models and maps, each imported by an rcbench process in every mode of its format.
TEST_F(Hostile, ModelsAndMapsForSceneImport) {
    ASSERT_NO_FATAL_FAILURE(make_bsp());
    rcb::Random r(rcb::mix_seed(1, 3));
    const std::string bsp = bases_["tiny.bsp"];
    const std::string gl = gltf().dump(2);
    base("model.obj", kObj);
    base("model.gltf", gl);
    const int n = mutants(160);
    for (int i = 0; i < n; ++i) {
        struct Kind {
            std::string ext, option;
            std::vector<std::string> modes;
        };
        const Kind kind = i % 4 == 0   ? Kind{".obj", "--model-mode", {"instances", "triangles"}}
                          : i % 4 == 1 ? Kind{".gltf", "--model-mode", {"instances", "triangles"}}
                          : i % 4 == 2 ? Kind{".bsp", "--bsp-mode", {"brushes", "triangles"}}
                                       : Kind{i % 8 == 3 ? ".pk3" : ".bsp", "--bsp-mode", {"brushes", "triangles"}};
        const Mutant m = kind.ext == ".obj"    ? mutate_obj(kObj, r)
                         : kind.ext == ".gltf" ? mutate_json(gltf(), r)
                         : kind.ext == ".pk3"  ? mutate_bytes(bsp, r)
                                               : mutate_words(bsp, r);
        const std::string f = input("model", kind.ext, m.bytes);
        std::vector<std::string> places = m.places;
        places.push_back(f);
        for (const std::string& mode : kind.modes) {
            const std::string out = fresh("imported", ".rcbscene");
            check("scene import " + kind.ext.substr(1),
                  {{"scene", "import", f, kind.option, mode, "--frames", "1", "--rays", "8", "-o", out},
                   places,
                   {out},
                   {f},
                   false,
                   m.what});
        }
        done(f);
    }
}

// ---------------------------------------------------------------------------------------------
// Experiment and tuning files, a tuner's results.

// Over 30 s: 400 mutants, each a `run --dry-run` process; every 8th also a whole run with its calibration.
TEST_F(Hostile, ExperimentFilesForRun) {
    ASSERT_NO_FATAL_FAILURE(make_experiment());
    const json doc = experiment();
    rcb::Random r(rcb::mix_seed(1, 4));
    const int n = mutants(400);
    for (int i = 0; i < n; ++i) {
        const Mutant m = mutate_json(doc, r);
        const std::string f = input("exp", ".json", m.bytes);
        std::vector<std::string> places = m.places;
        places.push_back(f);
        check("run --dry-run", {{"run", f, "--dry-run", "--db", "dry.db"}, places, {}, {f}, false, m.what});
        if (i % 8 == 0) {
            const std::string db = fresh("run", ".db");
            check("run", {{"run", f, "--db", db}, places, {db}, {f}, false, m.what});
        }
        done(f);
    }
}

TEST_F(Hostile, TuningFilesForTune) {
    ASSERT_NO_FATAL_FAILURE(make_recording());
    const json doc = tuning();
    rcb::Random r(rcb::mix_seed(1, 5));
    const int n = mutants(100);
    for (int i = 0; i < n; ++i) {
        const Mutant m = mutate_json(doc, r);
        const std::string f = input("tune", ".json", m.bytes);
        std::vector<std::string> places = m.places;
        places.push_back(f);
        const std::string db = fresh("tune", ".db");
        check("tune", {{"tune", f, "--db", db, "--out-dir", "out"}, places, {db, "out/"}, {f}, false, m.what});
        done(f);
    }
}

TEST_F(Hostile, TuningResultsForAdvise) {
    ASSERT_NO_FATAL_FAILURE(make_tuning_result());
    const json doc = json::parse(bases_["tr.json"]);
    rcb::Random r(rcb::mix_seed(1, 6));
    const int n = mutants(100);
    for (int i = 0; i < n; ++i) {
        const Mutant m = mutate_json(doc, r);
        const std::string f = input("tuning", ".json", m.bytes);
        std::vector<std::string> places = m.places;
        places.push_back(f);
        check("advise --tuning",
              {{"advise", "base.rcbscene", "--tuning", f, "--category", "tiny", "--repetitions", "1"},
               places,
               {},
               {f},
               false,
               m.what});
        done(f);
    }
}

/// Inputs at the edges the runner, the tuner and the result commands used to get wrong: values a
/// range lets past a check, two names for one scene, a tuning without rays, explicit zero or
/// empty values, and errors that were not one line naming their place.
TEST_F(Hostile, EdgesOfRunTuneMergeAndAdvise) {
    ASSERT_NO_FATAL_FAILURE(make_database());
    ASSERT_NO_FATAL_FAILURE(make_tuning_result());
    auto experiment_with = [](const std::string& scenes, const std::string& structures, const std::string& extra) {
        return R"({"frames": 2, "rays_per_frame": 8, )" + extra + R"("scenes": )" + scenes + R"(, "structures": )" +
               structures + "}";
    };
    const std::string one_scene = R"([{"preset": "uni-s"}])";
    std::vector<Case> cases;
    auto dry_run = [&](const std::string& text, const std::vector<std::string>& places, const std::string& what) {
        const std::string f = input("edge", ".json", text);
        cases.push_back({.args = {"run", f, "--dry-run"}, .places = places, .inputs = {f}, .bad = true, .what = what});
    };
    dry_run(experiment_with(one_scene,
                            R"([{"name": "wbvh", "grids": [{"cast_threads": {"from": 1, "to": 8, "step": 1}}]}])", ""),
            {"structures[0].grids[0].cast_threads"}, "cast_threads range beyond the run's threads");
    dry_run(experiment_with(one_scene,
                            R"([{"name": "lbvh", "grids": [{"threads": {"from": 1, "to": 64, "times": 2}}]}])", ""),
            {"structures[0].grids[0].threads"}, "threads geometric range beyond the run's threads");
    dry_run(experiment_with(R"([{"preset": "uni-s", "name": "a"}, {"preset": "uni-s", "name": "b"}])",
                            R"([{"name": "bf"}])", ""),
            {"scenes[1]"}, "one scene under two names");
    dry_run(
        experiment_with(R"([{"recording": "base.rcbscene", "name": "a"}, {"recording": "base.rcbscene", "name": "b"}])",
                        R"([{"name": "bf"}])", ""),
        {"scenes[1]"}, "one recording under two names");
    {
        const std::string f = input(
            "edge", ".json",
            experiment_with(R"([{"recording": "base.rcbscene"}])", R"([{"name": "bf"}])", R"("warmup_frames": 3, )"));
        const std::string db = fresh("edge", ".db");
        cases.push_back({.args = {"run", f, "--db", db},
                         .places = {"warmup_frames"},
                         .writes = {db},
                         .inputs = {f},
                         .bad = true,
                         .what = "warm-up that leaves none of a recording's frames"});
    }
    auto tune = [&](const json& doc, const std::vector<std::string>& places, const std::string& what) {
        const std::string f = input("edge-tune", ".json", doc.dump());
        const std::string db = fresh("edge-tune", ".db");
        cases.push_back({.args = {"tune", f, "--db", db, "--out-dir", "edge-out"},
                         .places = places,
                         .writes = {db, "edge-out/"},
                         .inputs = {f},
                         .bad = true,
                         .what = what});
    };
    json no_rays = tuning();
    no_rays["rays_per_frame"] = 0;
    no_rays["categories"][0]["scenes"] = json::array({json{{"preset", "uni-s"}, {"frames", 2}}});
    tune(no_rays, {"rays_per_frame"}, "a tuning without rays");

    // A merge input whose frame index lost its rows (an empty leaf page in place of its root).
    std::string damaged = bases_["r.db"];
    {
        rcb::Database db((work_ / "r.db").string(), true);
        rcb::Statement root = db.prepare("SELECT rootpage FROM sqlite_master WHERE name = 'sqlite_autoindex_frame_1'");
        rcb::Statement size = db.prepare("PRAGMA page_size");
        ASSERT_TRUE(root.step() && size.step());
        const std::size_t at = std::size_t((root.int64(0) - 1) * size.int64(0));
        ASSERT_LT(at + 8, damaged.size());
        damaged.replace(at, 8, std::string("\x0a\0\0\0\0\0\0\0", 8));
    }
    const std::string bad_db = input("edge-damaged", ".db", damaged);
    cases.push_back({.args = {"merge", "edge-merged.db", bad_db},
                     .places = {bad_db},
                     .writes = {"edge-merged.db"},
                     .inputs = {bad_db},
                     .bad = true,
                     .what = "merge of a database with a damaged index"});
    cases.push_back({.args = {"categories", "r.db", "--run", "0"}, .places = {"--run"}, .bad = true, .what = "run 0"});
    cases.push_back({.args = {"fit", "r.db", "--experiment", ""},
                     .places = {"--experiment"},
                     .bad = true,
                     .what = "empty experiment"});
    cases.push_back({.args = {"advise", "base.rcbscene", "--tuning", "tr.json", "--category", ""},
                     .places = {"--category"},
                     .bad = true,
                     .what = "empty category"});
    json kd = json::parse(bases_["tr.json"]);
    for (json& c : kd["categories"])
        for (json& st : c["structures"]) st["structure"] = "kd";
    const std::string tr = input("edge-tr", ".json", kd.dump());
    cases.push_back({.args = {"advise", "base.rcbscene", "--tuning", tr, "--category", "tiny", "--repetitions", "1"},
                     .places = {tr},
                     .inputs = {tr},
                     .bad = true,
                     .what = "a tuning naming structure kd"});
    for (const Case& c : cases) {
        check("edges: " + c.args[0], c);
        for (const std::string& f : c.inputs) done(f);
    }
    // A limit in a message reads as the file writes it, not as ±1000000000000000.000000.
    EXPECT_EQ(rcb::shape_problem(rcb::Shape::sphere({1e15f, 0, 0}, 1e14f), rcb::kMaxCoordinate),
              "sphere reaches beyond ±1e+15");
}

// ---------------------------------------------------------------------------------------------
// Results databases: damaged bytes, and well-formed SQLite holding values rcbench never writes.

TEST_F(Hostile, DatabasesForQueryCompareMergeFitReport) {
    ASSERT_NO_FATAL_FAILURE(make_database());
    const std::string good = bases_["r.db"];
    // Statements that leave a readable database with hostile contents (NULLs, text for numbers,
    // extremes, missing rows and tables, broken JSON, a schema version from the future).
    const std::vector<std::string> sql = {
        "UPDATE cell SET raycast_ns_median = NULL",
        "UPDATE cell SET raycast_ns_median = 'abc', update_ns_median = x'00ff'",
        "UPDATE cell SET raycast_ns_median = 1e308, update_ns_median = -1e308",
        "UPDATE cell SET raycast_ns_median = -1, build_ns = -9223372036854775808",
        "UPDATE frame SET raycast_ns = NULL, update_ns = NULL",
        "UPDATE frame SET raycast_ns = 9223372036854775807, n_t = -1, n_rb = 1e300, n_tp = 'x'",
        "UPDATE frame SET rays = 0, hits = -5",
        "UPDATE frame SET warmup = 1",
        "UPDATE frame SET stats = '" + nested(50000, false, true) + "'",
        "UPDATE frame SET stats = 'not json', memory_bytes = -1",
        "UPDATE config SET params = 'not json'",
        "UPDATE config SET params = '{\"density\": 1e999}'",
        "UPDATE config SET params = '" + nested(50000, true, true) + "'",
        "UPDATE config SET structure = 'kdtree'",
        "UPDATE config SET structure = NULL",
        "UPDATE scene SET name = '" + std::string(5'000'000, 'n') + "'",
        "UPDATE scene SET stats = '{', meta = x'ff00fe'",
        "UPDATE scene SET objects = -1, frames = 0, rays_per_frame = 1e308",
        "UPDATE run SET finished_at = NULL",
        "UPDATE run SET started_at = 'yesterday', finished_at = 'never'",
        "UPDATE run SET experiment_content = '" + nested(50000, false, false) + "'",
        "UPDATE run SET experiment_id = 999",
        "UPDATE run SET uuid = NULL",
        "UPDATE run SET uuid = (SELECT min(uuid) FROM run)",
        "UPDATE run SET git_commit = 'a\nb', cpu_model = '\x1b[31m'",
        "UPDATE cell SET run_id = 999",
        "UPDATE cell SET repetition = 9223372036854775807",
        "UPDATE cell SET frames = 0, mismatches = -1",
        "UPDATE cell SET config_id = NULL",
        "UPDATE cell SET scene_id = 424242",
        "DELETE FROM frame",
        "DELETE FROM cell",
        "DELETE FROM config",
        "DELETE FROM scene",
        "DELETE FROM run WHERE id = 1",
        "DELETE FROM experiment",
        "DROP VIEW cell_summary",
        "DROP TABLE frame",
        "DROP TABLE cell",
        "PRAGMA user_version = 99",
        "PRAGMA user_version = 0",
        "PRAGMA user_version = -1",
        "CREATE TABLE zz(x); INSERT INTO zz VALUES (1)",
        "PRAGMA journal_mode = DELETE",
    };
    rcb::Random r(rcb::mix_seed(1, 7));
    const int n_sql = kSanitized ? int(sql.size() / 3) : int(sql.size());
    const int n_bytes = mutants(40);
    for (int i = 0; i < n_sql + n_bytes; ++i) {
        std::string what;
        std::string bytes;
        if (i < n_sql) {
            const std::size_t k = kSanitized ? r.below(sql.size()) : std::size_t(i);
            const fs::path tmp = root_ / "mutating.db";
            write_bytes(tmp, good);
            try {
                rcb::Database db(tmp.string(), false);
                db.exec("PRAGMA foreign_keys = OFF");  // a damaged database need not keep its references
                db.exec(sql[k]);
            } catch (const std::exception& e) {
                // SQLite itself refuses some damage (NOT NULL, UNIQUE): such a file cannot exist.
                const std::string why = e.what();
                if (why.find("constraint failed") == std::string::npos)
                    ADD_FAILURE() << "could not apply " << sql[k].substr(0, 80) << ": "
                                  << why;  // the schema changed: update the list
                continue;
            }
            bytes = read_bytes(tmp);
            fs::remove(tmp);
            what = sql[k].size() > 120 ? sql[k].substr(0, 100) + "...(" + std::to_string(sql[k].size()) + " bytes)"
                                       : sql[k];
        } else {
            Mutant m;
            switch (r.below(4)) {
                case 0: {  // the 100-byte header
                    m.bytes = good;
                    const std::size_t p = r.below(100);
                    m.bytes[p] = char(m.bytes[p] ^ (1 << r.below(8)));
                    m.what = "header byte " + std::to_string(p) + " flipped";
                    break;
                }
                case 1: {  // cut at a page boundary
                    const std::size_t pages = good.size() / 4096;
                    const std::size_t keep = 4096 * r.below(pages);
                    m = {good.substr(0, keep), "truncated to " + std::to_string(keep / 4096) + " pages", {}};
                    break;
                }
                case 2: {  // a page zeroed
                    m.bytes = good;
                    const std::size_t page = r.below(good.size() / 4096);
                    std::fill(m.bytes.begin() + std::ptrdiff_t(page * 4096),
                              m.bytes.begin() + std::ptrdiff_t(page * 4096 + 4096), '\0');
                    m.what = "page " + std::to_string(page) + " zeroed";
                    break;
                }
                default:
                    m = mutate_bytes(good, r);
            }
            bytes = m.bytes;
            what = m.what;
        }
        const std::string f = input("db", ".db", bytes);
        const std::string out = fresh("merged", ".db"), html = fresh("report", ".html");
        // Errors about the contents may name the run instead of the file.
        const std::vector<std::string> places{f}, content_places{f, "run ", "runs "};
        check("query", {{"query", f, "SELECT * FROM cell_summary"}, {f, "query"}, {}, {f}, false, what});
        check("query", {{"query", "--csv", f, "SELECT * FROM frame"}, {f, "query"}, {}, {f}, false, what});
        check("compare", {{"compare", f, "--baseline", "1", "--candidate", "2"},
                          {f, "run ", "runs ", "--baseline", "--candidate"},
                          {},
                          {f},
                          false,
                          what});
        check("merge", {{"merge", out, f}, places, {out}, {f}, false, what});
        if (i < n_sql || i % 2 == 0)  // gnuplot makes a report the slowest command here
            check("report", {{"report", f, "-o", html}, content_places, {html}, {f}, false, what});
        check("fit", {{"fit", f}, content_places, {f}, {f}, false, what});
        done(f);
    }
}

// ---------------------------------------------------------------------------------------------
// Hostile arguments, and outputs that alias inputs or cannot be written.

TEST_F(Hostile, ArgumentsOfSceneCommands) {
    ASSERT_NO_FATAL_FAILURE(make_recording());
    ASSERT_NO_FATAL_FAILURE(make_csvs());
    ASSERT_NO_FATAL_FAILURE(make_bsp());
    fs::create_directories(work_ / "adir");
    // Linux passes at most 128 KiB in one argument (MAX_ARG_STRLEN); files get 5 MB instead.
    const std::string big(131000, 'x');
    const std::string long_name(5000, 'n');
    auto gen = [](std::vector<std::string> extra) {
        std::vector<std::string> a{"scene", "gen", "--preset", "uni-s", "--frames", "1", "--rays", "4"};
        a.insert(a.end(), extra.begin(), extra.end());
        return a;
    };
    std::vector<Case> cases = {
        {.args = gen({"--seed", "-1", "-o", "g.rcbscene"}),
         .places = {"--seed"},
         .writes = {"g.rcbscene"},
         .what = "negative seed"},
        {.args = gen({"--seed", "18446744073709551616", "-o", "g.rcbscene"}),
         .places = {"--seed"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "seed 2^64"},
        {.args = gen({"--seed", "18446744073709551615", "-o", "g.rcbscene"}),
         .places = {"--seed"},
         .writes = {"g.rcbscene"},
         .what = "seed 2^64-1"},
        {.args = gen({"--seed", "1e3", "-o", "g.rcbscene"}),
         .places = {"--seed"},
         .writes = {"g.rcbscene"},
         .what = "seed 1e3"},
        {.args = gen({"--seed", "", "-o", "g.rcbscene"}),
         .places = {"--seed"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "empty seed"},
        {.args = gen({"--seed", big, "-o", "g.rcbscene"}),
         .places = {"--seed"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "128 KB seed"},
        {.args = {"scene", "gen", "--preset", "uni-s", "--frames", "-1", "-o", "g.rcbscene"},
         .places = {"--frames"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "frames -1"},
        {.args = {"scene", "gen", "--preset", "uni-s", "--frames", "4294967296", "-o", "g.rcbscene"},
         .places = {"--frames"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "frames 2^32"},
        {.args = {"scene", "gen", "--preset", "uni-s", "--rays", "100000000", "-o", "g.rcbscene"},
         .places = {"--rays", "rays"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "10 frames of 10^8 rays"},
        {.args = {"scene", "gen", "--preset", "uni-s", "--rays", "-1", "-o", "g.rcbscene"},
         .places = {"--rays"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "rays -1"},
        {.args = {"scene", "gen", "--preset", "uni-s", "--rays", "4294967296", "-o", "g.rcbscene"},
         .places = {"--rays"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "rays 2^32"},
        {.args = {"scene", "gen", "--generator", "irregular", "--objects", "100000000", "-o", "g.rcbscene"},
         .places = {"--objects", "objects"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "10^8 objects"},
        {.args = {"scene", "gen", "--generator", "uniform", "--objects", "0", "-o", "g.rcbscene"},
         .places = {"--objects"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "0 objects"},
        {.args = {"scene", "gen", "--generator", "uniform", "--objects", "-5", "-o", "g.rcbscene"},
         .places = {"--objects"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "-5 objects"},
        {.args = gen({"--change-fraction", "nan", "-o", "g.rcbscene"}),
         .places = {"--change-fraction"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "change fraction nan"},
        {.args = gen({"--change-fraction", "inf", "-o", "g.rcbscene"}),
         .places = {"--change-fraction"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "change fraction inf"},
        {.args = gen({"--change-fraction", "-0", "-o", "g.rcbscene"}),
         .places = {"--change-fraction"},
         .writes = {"g.rcbscene"},
         .what = "change fraction -0"},
        {.args = gen({"--change-fraction", "1e-320", "-o", "g.rcbscene"}),
         .places = {"--change-fraction"},
         .writes = {"g.rcbscene"},
         .what = "change fraction denormal"},
        {.args = gen({"--change-fraction", "1.0000001", "-o", "g.rcbscene"}),
         .places = {"--change-fraction"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "change fraction > 1"},
        {.args = gen({"--insert-share", "nan", "-o", "g.rcbscene"}),
         .places = {"--insert-share"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "insert share nan"},
        {.args = gen({"--remove-share", "nan", "-o", "g.rcbscene"}),
         .places = {"--remove-share"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "remove share nan"},
        {.args = gen({"--insert-share", "0.6", "--remove-share", "0.6", "-o", "g.rcbscene"}),
         .places = {"--insert-share", "--remove-share"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "shares over 1"},
        {.args = gen({"--move-scale", "nan", "-o", "g.rcbscene"}),
         .places = {"--move-scale"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "move scale nan"},
        {.args = gen({"--move-scale", "1e308", "-o", "g.rcbscene"}),
         .places = {"--move-scale"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "move scale 1e308"},
        {.args = gen({"--move-scale", "1000", "--change-fraction", "1", "-o", "g.rcbscene"}),
         .places = {"--move-scale"},
         .writes = {"g.rcbscene"},
         .what = "move scale 1000"},
        {.args = gen({"--ray-mix", "center:nan", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix", "center:nan"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "ray weight nan"},
        {.args = gen({"--ray-mix", "center:1e999", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix", "center:1e999"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "ray weight 1e999"},
        {.args = gen({"--ray-mix", "center:-1", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix", "center:-1"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "ray weight -1"},
        {.args = gen({"--ray-mix", "center:0", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix", "center:0"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "all ray weights 0"},
        {.args = gen({"--ray-mix", "center:1e-320,los:1e-320", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix"},
         .writes = {"g.rcbscene"},
         .what = "denormal ray weights"},
        {.args = gen({"--ray-mix", "", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "empty ray mix"},
        {.args = gen({"--ray-mix", ":", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "ray mix ':'"},
        {.args = gen({"--ray-mix", "center:", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix", "center:"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "ray mix without weight"},
        {.args = gen({"--ray-mix", "center\nlos", "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "ray mix with a newline"},
        {.args = gen({"--ray-mix", big, "-o", "g.rcbscene"}),
         .places = {"--ray-mix", "ray mix"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "128 KB ray mix"},
        {.args = {"scene", "gen", "--preset", "", "-o", "g.rcbscene"},
         .places = {"--preset"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "empty preset"},
        {.args = {"scene", "gen", "--generator", "", "--objects", "5", "-o", "g.rcbscene"},
         .places = {"--generator"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "empty generator"},
        {.args = gen({"-o", ""}), .places = {"-o", "--output"}, .bad = true, .what = "empty output"},
        {.args = gen({"-o", "adir"}), .places = {"-o", "--output", "adir"}, .bad = true, .what = "output is a folder"},
        {.args = gen({"-o", "/proc/self/x.rcbscene"}),
         .places = {"-o", "--output", "/proc/self/x.rcbscene"},
         .bad = true,
         .what = "output in /proc/self"},
        {.args = gen({"-o", long_name}),
         .places = {"-o", "--output", long_name.substr(0, 50)},
         .bad = true,
         .what = "5000-byte output name"},
        {.args = gen({"-o", "base.rcbscene/x"}),
         .places = {"-o", "--output", "base.rcbscene"},
         .bad = true,
         .what = "output under a file"},
        // import
        {.args = {"scene", "import", "boxes.csv", "-o", "boxes.csv"},
         .places = {"-o", "--output", "boxes.csv"},
         .bad = true,
         .what = "import output = input"},
        {.args = {"scene", "import", "tiny.bsp", "-o", "tiny.bsp"},
         .places = {"-o", "--output", "tiny.bsp"},
         .bad = true,
         .what = "import output = input (bsp)"},
        {.args = {"scene", "import", "./boxes.csv", "-o", "boxes.csv"},
         .places = {"-o", "--output", "boxes.csv"},
         .bad = true,
         .what = "import output = input, other spelling"},
        {.args = {"scene", "import", "boxes.csv", "-o", "adir"},
         .places = {"-o", "--output", "adir"},
         .bad = true,
         .what = "import output is a folder"},
        {.args = {"scene", "import", "boxes.csv", "--frames", "100", "--rays", "100000000", "-o", "i.rcbscene"},
         .places = {"--rays", "rays"},
         .writes = {"i.rcbscene"},
         .bad = true,
         .what = "import 100 frames of 10^8 rays"},
        {.args = {"scene", "import", "boxes.csv", "--change-fraction", "nan", "-o", "i.rcbscene"},
         .places = {"--change-fraction"},
         .writes = {"i.rcbscene"},
         .bad = true,
         .what = "import change fraction nan"},
        {.args = {"scene", "import", "base.rcbscene", "-o", "i.rcbscene"},
         .places = {"base.rcbscene"},
         .writes = {"i.rcbscene"},
         .bad = true,
         .what = "import a recording"},
        {.args = {"scene", "import", "/dev/zero", "-o", "i.rcbscene"},
         .places = {"/dev/zero"},
         .writes = {"i.rcbscene"},
         .bad = true,
         .what = "import /dev/zero"},
        {.args = {"scene", "import", "adir", "-o", "i.rcbscene"},
         .places = {"adir"},
         .writes = {"i.rcbscene"},
         .bad = true,
         .what = "import a folder"},
        {.args = {"scene", "import", "", "-o", "i.rcbscene"},
         .places = {"input", "''"},
         .writes = {"i.rcbscene"},
         .bad = true,
         .what = "import an empty path"},
        {.args = {"scene", "import", "tiny.bsp", "--map", "../../../etc/passwd", "-o", "i.rcbscene"},
         .places = {"--map", "tiny.bsp"},
         .writes = {"i.rcbscene"},
         .what = "--map on a .bsp"},
        // info, simulate, cast
        {.args = {"scene", "info", "adir"}, .places = {"adir"}, .bad = true, .what = "info on a folder"},
        {.args = {"scene", "info", "/dev/zero"}, .places = {"/dev/zero"}, .bad = true, .what = "info on /dev/zero"},
        {.args = {"scene", "info", "boxes.csv"}, .places = {"boxes.csv"}, .bad = true, .what = "info on a CSV"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--warmup", "3"},
         .places = {"--warmup", "warm-up"},
         .bad = true,
         .what = "warmup = frames"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--warmup", "2", "--frames", "2"},
         .places = {"--warmup", "warm-up"},
         .bad = true,
         .what = "warmup = --frames"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--warmup", "18446744073709551616"},
         .places = {"--warmup", "warm-up"},
         .bad = true,
         .what = "warmup 2^64"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--frames", "-1"},
         .places = {"--frames"},
         .bad = true,
         .what = "frames -1"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--frames", "18446744073709551616"},
         .places = {"--frames"},
         .bad = true,
         .what = "frames 2^64"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", ""},
         .places = {"--structure", "structure"},
         .bad = true,
         .what = "empty structure"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "all", "--param", "density=2"},
         .places = {"--param"},
         .bad = true,
         .what = "param with all"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "ug", "--param", "density=nan"},
         .places = {"--param", "density"},
         .bad = true,
         .what = "density nan"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "ug", "--param", "density=1e999"},
         .places = {"--param", "density"},
         .bad = true,
         .what = "density 1e999"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "ug", "--param", "density=1e-320"},
         .places = {"--param", "density"},
         .bad = true,
         .what = "density denormal"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "hg", "--param",
                  "max_depth=18446744073709551616"},
         .places = {"--param", "max_depth"},
         .bad = true,
         .what = "max_depth 2^64"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "hg", "--param", "max_capacity=-1"},
         .places = {"--param", "max_capacity"},
         .bad = true,
         .what = "max_capacity -1"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "hg", "--param", "max_capacity=4294967296"},
         .places = {"--param", "max_capacity"},
         .bad = true,
         .what = "max_capacity 2^32"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "ug", "--param", "density"},
         .places = {"--param", "density"},
         .bad = true,
         .what = "param without ="},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "ug", "--param", "=1"},
         .places = {"--param"},
         .bad = true,
         .what = "param without name"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "ug", "--param", "density="},
         .places = {"--param", "density"},
         .bad = true,
         .what = "param without value"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "dbvh", "--param", "mode=" + big},
         .places = {"--param", "mode"},
         .bad = true,
         .what = "128 KB mode"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--json-out", "base.rcbscene"},
         .places = {"--json-out", "base.rcbscene"},
         .bad = true,
         .what = "--json-out = the scene"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--json-out", "./base.rcbscene"},
         .places = {"--json-out", "base.rcbscene"},
         .bad = true,
         .what = "--json-out = the scene, other spelling"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--json-out", "adir"},
         .places = {"--json-out", "adir"},
         .bad = true,
         .what = "--json-out is a folder"},
        {.args = {"simulate", "--scene", "base.rcbscene", "--structure", "bf", "--json-out", "/proc/self/x.json"},
         .places = {"--json-out", "/proc/self/x.json"},
         .bad = true,
         .what = "--json-out in /proc/self"},
        {.args = {"simulate", "--scene", "adir", "--structure", "bf"},
         .places = {"adir"},
         .bad = true,
         .what = "scene is a folder"},
        {.args = {"simulate", "--scene", "/dev/zero", "--structure", "bf"},
         .places = {"/dev/zero"},
         .bad = true,
         .what = "scene /dev/zero"},
        {.args = {"simulate", "--scene", "", "--structure", "bf"},
         .places = {"--scene", "''"},
         .bad = true,
         .what = "empty scene path"},
        {.args = {"cast", "--scene", "boxes.csv", "--rays", "boxes.csv", "--structure", "bf"},
         .places = {"boxes.csv"},
         .bad = true,
         .what = "boxes as rays"},
        {.args = {"cast", "--scene", "boxes.csv", "--rays", "/dev/zero", "--structure", "bf"},
         .places = {"/dev/zero"},
         .bad = true,
         .what = "rays /dev/zero"},
        {.args = {"cast", "--scene", "boxes.csv", "--rays", "adir", "--structure", "bf"},
         .places = {"adir"},
         .bad = true,
         .what = "rays is a folder"},
        {.args = {"cast", "--scene", "rays.csv", "--rays", "rays.csv", "--structure", "bf"},
         .places = {"rays.csv"},
         .bad = true,
         .what = "rays as boxes"},
        {.args = {"cast", "--scene", "tiny.bsp", "--rays", "rays.csv", "--structure", "bf"},
         .places = {"tiny.bsp"},
         .what = "cast on a map"},
        // advise
        {.args = {"advise", "base.rcbscene", "--repetitions", "0"},
         .places = {"--repetitions"},
         .bad = true,
         .what = "0 repetitions"},
        {.args = {"advise", "base.rcbscene", "--repetitions", "-1"},
         .places = {"--repetitions"},
         .bad = true,
         .what = "-1 repetitions"},
        {.args = {"advise", "base.rcbscene", "--repetitions", "18446744073709551616"},
         .places = {"--repetitions"},
         .bad = true,
         .what = "2^64 repetitions"},
        {.args = {"advise", "base.rcbscene", "--warmup", "3"},
         .places = {"--warmup", "warm-up"},
         .bad = true,
         .what = "warmup = frames"},
        {.args = {"advise", "base.rcbscene", "--warmup", "18446744073709551616"},
         .places = {"--warmup", "warm-up"},
         .bad = true,
         .what = "warmup 2^64"},
        {.args = {"advise", "base.rcbscene", "--warmup", "-1"},
         .places = {"--warmup", "warm-up"},
         .bad = true,
         .what = "warmup -1"},
        {.args = {"advise", "base.rcbscene", "--tuning", "base.rcbscene", "--category", "tiny"},
         .places = {"--tuning", "base.rcbscene"},
         .bad = true,
         .what = "a recording as tuning"},
        {.args = {"advise", "base.rcbscene", "--tuning", "missing.json", "--category", "tiny"},
         .places = {"--tuning", "missing.json"},
         .bad = true,
         .what = "missing tuning"},
        {.args = {"advise", "base.rcbscene", "--tuning", "/dev/zero", "--category", "tiny"},
         .places = {"--tuning", "/dev/zero"},
         .bad = true,
         .what = "tuning /dev/zero"},
        {.args = {"advise", "base.rcbscene", "--category", "tiny"},
         .places = {"--tuning", "--category"},
         .bad = true,
         .what = "category without tuning"},
        {.args = {"advise", "base.rcbscene", "--accuracy", "recall>=nan"},
         .places = {"--accuracy"},
         .bad = true,
         .what = "accuracy NaN"},
        {.args = {"advise", "base.rcbscene", "--accuracy", "precision>=1e308"},
         .places = {"--accuracy"},
         .bad = true,
         .what = "accuracy 1e308"},
        {.args = {"advise", "base.rcbscene", "--accuracy", "recall>="},
         .places = {"--accuracy"},
         .bad = true,
         .what = "accuracy no bound"},
        {.args = {"advise", "base.rcbscene", "--accuracy", ""},
         .places = {"--accuracy"},
         .bad = true,
         .what = "accuracy empty"},
        {.args = {"advise", "/dev/zero"}, .places = {"/dev/zero"}, .bad = true, .what = "advise /dev/zero"},
        {.args = {"advise", "adir"}, .places = {"adir"}, .bad = true, .what = "advise a folder"},
        {.args = {"advise", "boxes.csv", "--repetitions", "1", "--warmup", "10"},
         .places = {"--warmup", "warm-up"},
         .bad = true,
         .what = "advise CSV warmup = frames"},
        {.args = {"advise", "base.rcbscene", "--method", "best"},
         .places = {"--method"},
         .bad = true,
         .what = "unknown method"},
        {.args = {"advise", "base.rcbscene", "--method", ""},
         .places = {"--method"},
         .bad = true,
         .what = "empty method"},
        {.args = {"advise", "base.rcbscene", "--verify-top", "17"},
         .places = {"--verify-top"},
         .bad = true,
         .what = "verify-top 17"},
        {.args = {"advise", "base.rcbscene", "--verify-top", "-1"},
         .places = {"--verify-top"},
         .bad = true,
         .what = "verify-top -1"},
        {.args = {"advise", "base.rcbscene", "--verify-top", "18446744073709551616"},
         .places = {"--verify-top"},
         .bad = true,
         .what = "verify-top 2^64"},
        {.args = {"advise", "base.rcbscene", "--exhaustive"},
         .places = {"--exhaustive", "--tuning"},
         .bad = true,
         .what = "exhaustive alone"},
        // the command line itself
        {.args = {}, .places = {"subcommand", "rcbench"}, .bad = true, .what = "no arguments"},
        {.args = {"--bogus"}, .places = {"--bogus"}, .bad = true, .what = "unknown option"},
        {.args = {"scene"}, .places = {"subcommand", "scene"}, .bad = true, .what = "scene without a subcommand"},
        {.args = {"scene", "gen", "--preset", "uni-s", "-o", "g.rcbscene", "--frames"},
         .places = {"--frames"},
         .writes = {"g.rcbscene"},
         .bad = true,
         .what = "option without value"},
        {.args = {"simulate", big},
         .places = {"simulate", "--scene", "--structure"},
         .bad = true,
         .what = "128 KB argument"},
    };
    for (const Case& c : cases) {
        const std::string command = c.args.empty()                              ? "(none)"
                                    : c.args[0] == "scene" && c.args.size() > 1 ? "scene " + c.args[1]
                                                                                : c.args[0];
        check("arguments: " + command.substr(0, 20), c);
    }
}

TEST_F(Hostile, ArgumentsOfResultCommands) {
    ASSERT_NO_FATAL_FAILURE(make_database());
    base("exp.json", read_bytes(work_ / "small.json"));
    base("tune.json", tuning().dump(2));
    fs::create_directories(work_ / "adir");
    // Linux passes at most 128 KiB in one argument (MAX_ARG_STRLEN); files get 5 MB instead.
    const std::string big(131000, 'x');
    auto dry = [](const std::string& shard) {
        return std::vector<std::string>{"run", "exp.json", "--dry-run", "--db", "d.db", "--shard", shard};
    };
    std::vector<Case> cases = {
        {.args = dry("1/18446744073709551616"), .places = {"--shard"}, .bad = true, .what = "shard of 2^64"},
        {.args = dry("18446744073709551616/3"), .places = {"--shard"}, .bad = true, .what = "shard 2^64 of 3"},
        {.args = dry("0/0"), .places = {"--shard"}, .bad = true, .what = "shard 0/0"},
        {.args = dry("1/0"), .places = {"--shard"}, .bad = true, .what = "shard 1/0"},
        {.args = dry("2/1"), .places = {"--shard"}, .bad = true, .what = "shard 2/1"},
        {.args = dry("-1/3"), .places = {"--shard"}, .bad = true, .what = "shard -1/3"},
        {.args = dry("1/-3"), .places = {"--shard"}, .bad = true, .what = "shard 1/-3"},
        {.args = dry("1/3/4"), .places = {"--shard"}, .bad = true, .what = "shard 1/3/4"},
        {.args = dry("1.5/3"), .places = {"--shard"}, .bad = true, .what = "shard 1.5/3"},
        {.args = dry("1/"), .places = {"--shard"}, .bad = true, .what = "shard 1/"},
        {.args = dry("/3"), .places = {"--shard"}, .bad = true, .what = "shard /3"},
        {.args = dry(" 1/3"), .places = {"--shard"}, .what = "shard with a space"},
        {.args = dry(big), .places = {"--shard"}, .bad = true, .what = "128 KB shard"},
        {.args = {"run", "exp.json", "--db", "n.db", "--run", "-1"},
         .places = {"--run"},
         .writes = {"n.db"},
         .bad = true,
         .what = "run -1"},
        {.args = {"run", "exp.json", "--db", "n.db", "--run", "18446744073709551616"},
         .places = {"--run"},
         .writes = {"n.db"},
         .bad = true,
         .what = "run 2^64"},
        {.args = {"run", "exp.json", "--db", "r.db", "--run", "999"},
         .places = {"--run", "999"},
         .bad = true,
         .what = "run 999"},
        {.args = {"run", "exp.json", "--db", "adir"},
         .places = {"--db", "adir"},
         .bad = true,
         .what = "db is a folder"},
        {.args = {"run", "exp.json", "--db", "exp.json"},
         .places = {"--db", "exp.json"},
         .bad = true,
         .what = "db = the experiment"},
        {.args = {"run", "exp.json", "--db", "./exp.json"},
         .places = {"--db", "exp.json"},
         .bad = true,
         .what = "db = the experiment, other spelling"},
        {.args = {"run", "exp.json", "--db", "base.rcbscene"},
         .places = {"--db", "base.rcbscene"},
         .bad = true,
         .what = "db = a recording the experiment reads"},
        {.args = {"run", "exp.json", "--db", "/proc/self/x.db"},
         .places = {"--db", "/proc/self/x.db"},
         .bad = true,
         .what = "db in /proc/self"},
        {.args = {"run", "exp.json", "--db", ""}, .places = {"--db"}, .bad = true, .what = "empty db"},
        {.args = {"run", "/dev/zero", "--db", "n.db"},
         .places = {"/dev/zero"},
         .writes = {"n.db"},
         .bad = true,
         .what = "experiment /dev/zero"},
        {.args = {"run", "adir", "--db", "n.db"},
         .places = {"adir"},
         .writes = {"n.db"},
         .bad = true,
         .what = "experiment is a folder"},
        {.args = {"run", "r.db", "--db", "n.db"},
         .places = {"r.db"},
         .writes = {"n.db"},
         .bad = true,
         .what = "a database as experiment"},
        {.args = {"run", "tune.json", "--db", "n.db"},
         .places = {"tune.json"},
         .writes = {"n.db"},
         .bad = true,
         .what = "a tuning file as experiment"},
        // query
        {.args = {"query", "r.db", ""}, .places = {"query", "sql"}, .bad = true, .what = "empty SQL"},
        {.args = {"query", "r.db", big}, .places = {"query"}, .bad = true, .what = "128 KB SQL"},
        {.args = {"query", "r.db", "SELECT 1; DELETE FROM cell"},
         .places = {"query"},
         .bad = true,
         .what = "a second statement that writes"},
        {.args = {"query", "r.db", "ATTACH DATABASE 'att.db' AS a"},
         .places = {"query"},
         .bad = true,
         .what = "ATTACH"},
        {.args = {"query", "r.db", "VACUUM INTO 'v.db'"}, .places = {"query"}, .bad = true, .what = "VACUUM INTO"},
        {.args = {"query", "r.db", "PRAGMA journal_mode = DELETE"},
         .places = {"query"},
         .bad = true,
         .what = "journal mode"},
        {.args = {"query", "r.db", "PRAGMA user_version = 5"},
         .places = {"query"},
         .bad = true,
         .what = "user_version"},
        {.args = {"query", "r.db", "SELECT load_extension('/nonexistent')"},
         .places = {"query"},
         .bad = true,
         .what = "load_extension"},
        {.args = {"query", "r.db", "SELECT randomblob(2000000000)"},
         .places = {"query"},
         .bad = true,
         .what = "2 GB blob"},
        {.args = {"query", "r.db", "SELECT 1e999, -0.0, 0.0/0, char(0), char(10), x'ff00'"},
         .places = {"query"},
         .what = "odd values"},
        {.args = {"query", "--csv", "r.db", "SELECT char(10) || '\"' || char(13), 9223372036854775807 + 1"},
         .places = {"query"},
         .what = "odd CSV values"},
        {.args = {"query", "base.rcbscene", "SELECT 1"},
         .places = {"base.rcbscene"},
         .bad = true,
         .what = "query a recording"},
        {.args = {"query", "exp.json", "SELECT 1"}, .places = {"exp.json"}, .bad = true, .what = "query a JSON file"},
        {.args = {"query", "/dev/zero", "SELECT 1"}, .places = {"/dev/zero"}, .bad = true, .what = "query /dev/zero"},
        {.args = {"query", "adir", "SELECT 1"}, .places = {"adir"}, .bad = true, .what = "query a folder"},
        {.args = {"query", "", "SELECT 1"}, .places = {"db", "''"}, .bad = true, .what = "query an empty path"},
        // compare
        {.args = {"compare", "r.db", "--baseline", "'; DROP TABLE run; --", "--candidate", "2"},
         .places = {"--baseline", "'; DROP TABLE run; --"},
         .bad = true,
         .what = "SQL in a run id"},
        {.args = {"compare", "r.db", "--baseline", "18446744073709551616", "--candidate", "2"},
         .places = {"--baseline"},
         .bad = true,
         .what = "baseline 2^64"},
        {.args = {"compare", "r.db", "--baseline", "-1", "--candidate", "2"},
         .places = {"--baseline", "'-1'"},
         .bad = true,
         .what = "baseline -1"},
        {.args = {"compare", "r.db", "--baseline", "", "--candidate", "2"},
         .places = {"--baseline"},
         .bad = true,
         .what = "empty baseline"},
        {.args = {"compare", "r.db", "--baseline", big, "--candidate", "2"},
         .places = {"--baseline"},
         .bad = true,
         .what = "128 KB baseline"},
        {.args = {"compare", "r.db", "--baseline", "1", "--candidate", "2", "--alpha", "nan"},
         .places = {"--alpha"},
         .bad = true,
         .what = "alpha nan"},
        {.args = {"compare", "r.db", "--baseline", "1", "--candidate", "2", "--alpha", "0"},
         .places = {"--alpha"},
         .bad = true,
         .what = "alpha 0"},
        {.args = {"compare", "r.db", "--baseline", "1", "--candidate", "2", "--fail-on-regression", "nan"},
         .places = {"--fail-on-regression"},
         .bad = true,
         .what = "fail-on-regression nan"},
        {.args = {"compare", "r.db", "--baseline", "1", "--candidate", "2", "--metric", ""},
         .places = {"--metric"},
         .bad = true,
         .what = "empty metric"},
        {.args = {"compare", "base.rcbscene", "--baseline", "1", "--candidate", "2"},
         .places = {"base.rcbscene"},
         .bad = true,
         .what = "compare a recording"},
        {.args = {"compare", "missing.db", "--baseline", "1", "--candidate", "2"},
         .places = {"missing.db"},
         .bad = true,
         .what = "compare a missing database"},
        // merge
        {.args = {"merge", "r.db", "r.db"}, .places = {"r.db"}, .bad = true, .what = "merge into itself"},
        {.args = {"merge", "./r.db", "r.db"},
         .places = {"r.db"},
         .bad = true,
         .what = "merge into itself, other spelling"},
        {.args = {"merge", "m.db", "r.db", "r.db"},
         .places = {"r.db"},
         .writes = {"m.db"},
         .what = "the same input twice"},
        {.args = {"merge", "adir", "r.db"}, .places = {"adir"}, .bad = true, .what = "merge into a folder"},
        {.args = {"merge", "exp.json", "r.db"}, .places = {"exp.json"}, .bad = true, .what = "merge into a JSON file"},
        {.args = {"merge", "base.rcbscene", "r.db"},
         .places = {"base.rcbscene"},
         .bad = true,
         .what = "merge into a recording"},
        {.args = {"merge", "m.db", "base.rcbscene"},
         .places = {"base.rcbscene"},
         .writes = {"m.db"},
         .bad = true,
         .what = "merge from a recording"},
        {.args = {"merge", "m.db", "missing.db"},
         .places = {"missing.db"},
         .writes = {"m.db"},
         .bad = true,
         .what = "merge from a missing database"},
        {.args = {"merge", "m.db", "/dev/zero"},
         .places = {"/dev/zero"},
         .writes = {"m.db"},
         .bad = true,
         .what = "merge from /dev/zero"},
        {.args = {"merge", "/proc/self/x.db", "r.db"},
         .places = {"/proc/self/x.db"},
         .bad = true,
         .what = "merge into /proc/self"},
        // fit
        {.args = {"fit", "r.db", "--run", "-1"}, .places = {"--run"}, .bad = true, .what = "fit run -1"},
        {.args = {"fit", "r.db", "--run", "18446744073709551616"},
         .places = {"--run"},
         .bad = true,
         .what = "fit run 2^64"},
        {.args = {"fit", "r.db", "--run", "999"}, .places = {"--run", "999"}, .bad = true, .what = "fit run 999"},
        {.args = {"fit", "r.db", "--experiment", big},
         .places = {"--experiment"},
         .bad = true,
         .what = "fit 128 KB experiment name"},
        {.args = {"fit", "r.db", "--experiment", "nope"},
         .places = {"--experiment", "nope"},
         .bad = true,
         .what = "fit unknown experiment"},
        {.args = {"fit", "base.rcbscene"}, .places = {"base.rcbscene"}, .bad = true, .what = "fit a recording"},
        {.args = {"fit", "exp.json"}, .places = {"exp.json"}, .bad = true, .what = "fit a JSON file"},
        {.args = {"fit", "missing.db"}, .places = {"missing.db"}, .bad = true, .what = "fit a missing database"},
        {.args = {"fit", "/dev/zero"}, .places = {"/dev/zero"}, .bad = true, .what = "fit /dev/zero"},
        {.args = {"fit", "adir"}, .places = {"adir"}, .bad = true, .what = "fit a folder"},
        // report
        {.args = {"report", "r.db", "-o", "r.db"},
         .places = {"-o", "--output", "r.db"},
         .bad = true,
         .what = "report over its database"},
        {.args = {"report", "r.db", "-o", "./r.db"},
         .places = {"-o", "--output", "r.db"},
         .bad = true,
         .what = "report over its database, other spelling"},
        {.args = {"report", "r.db", "-o", "adir"},
         .places = {"-o", "--output", "adir"},
         .bad = true,
         .what = "report into a folder"},
        {.args = {"report", "r.db", "-o", "/proc/self/x.html"},
         .places = {"-o", "--output", "/proc/self/x.html"},
         .bad = true,
         .what = "report into /proc/self"},
        {.args = {"report", "r.db", "-o", ""},
         .places = {"-o", "--output"},
         .bad = true,
         .what = "report to an empty path"},
        {.args = {"report", "r.db", "-o", "rep.html", "--run", "18446744073709551616"},
         .places = {"--run"},
         .writes = {"rep.html"},
         .bad = true,
         .what = "report run 2^64"},
        {.args = {"report", "r.db", "-o", "rep.html", "--run", "-1"},
         .places = {"--run"},
         .writes = {"rep.html"},
         .bad = true,
         .what = "report run -1"},
        {.args = {"report", "missing.db", "-o", "rep.html"},
         .places = {"missing.db"},
         .writes = {"rep.html"},
         .bad = true,
         .what = "report a missing database"},
        {.args = {"report", "base.rcbscene", "-o", "rep.html"},
         .places = {"base.rcbscene"},
         .writes = {"rep.html"},
         .bad = true,
         .what = "report a recording"},
        // tune
        {.args = {"tune", "tune.json", "--db", "t.db", "--out-dir", "out", "--seed", "18446744073709551616"},
         .places = {"--seed"},
         .writes = {"t.db", "out/"},
         .bad = true,
         .what = "tune seed 2^64"},
        {.args = {"tune", "tune.json", "--db", "t.db", "--out-dir", "out", "--accuracy", "precision>=-0.5"},
         .places = {"--accuracy"},
         .writes = {"t.db", "out/"},
         .bad = true,
         .what = "tune accuracy below 0"},
        {.args = {"tune", "tune.json", "--db", "t.db", "--out-dir", "out", "--accuracy", "recall=0.9"},
         .places = {"--accuracy"},
         .writes = {"t.db", "out/"},
         .bad = true,
         .what = "tune accuracy without >="},
        {.args = {"tune", "tune.json", "--db", "t.db", "--out-dir", "out", "--seed", "-1"},
         .places = {"--seed"},
         .writes = {"t.db", "out/"},
         .what = "tune seed -1"},
        {.args = {"tune", "tune.json", "--db", "t.db", "--out-dir", "/proc/self"},
         .places = {"--out-dir", "/proc/self"},
         .writes = {"t.db"},
         .bad = true,
         .what = "out-dir /proc/self"},
        {.args = {"tune", "tune.json", "--db", "t.db", "--out-dir", "tune.json"},
         .places = {"--out-dir", "tune.json"},
         .writes = {"t.db"},
         .bad = true,
         .what = "out-dir is a file"},
        {.args = {"tune", "tune.json", "--db", "t.db", "--out-dir", ""},
         .places = {"--out-dir"},
         .writes = {"t.db"},
         .bad = true,
         .what = "empty out-dir"},
        {.args = {"tune", "tune.json", "--db", "tune.json", "--out-dir", "out"},
         .places = {"--db", "tune.json"},
         .writes = {"out/"},
         .bad = true,
         .what = "db = the tuning file"},
        {.args = {"tune", "tune.json", "--db", "base.rcbscene", "--out-dir", "out"},
         .places = {"--db", "base.rcbscene"},
         .writes = {"out/"},
         .bad = true,
         .what = "db = a recording it reads"},
        {.args = {"tune", "tune.json", "--db", "adir", "--out-dir", "out"},
         .places = {"--db", "adir"},
         .writes = {"out/"},
         .bad = true,
         .what = "db is a folder"},
        {.args = {"tune", "exp.json", "--db", "t.db", "--out-dir", "out"},
         .places = {"exp.json"},
         .writes = {"t.db", "out/"},
         .bad = true,
         .what = "an experiment as tuning file"},
        {.args = {"tune", "r.db", "--db", "t.db", "--out-dir", "out"},
         .places = {"r.db"},
         .writes = {"t.db", "out/"},
         .bad = true,
         .what = "a database as tuning file"},
        {.args = {"tune", "/dev/zero", "--db", "t.db", "--out-dir", "out"},
         .places = {"/dev/zero"},
         .writes = {"t.db", "out/"},
         .bad = true,
         .what = "tune /dev/zero"},
        {.args = {"tune", "missing.json", "--db", "t.db", "--out-dir", "out"},
         .places = {"missing.json"},
         .writes = {"t.db", "out/"},
         .bad = true,
         .what = "tune a missing file"},
    };
    for (const Case& c : cases) check("arguments: " + c.args[0], c);
}

// ---------------------------------------------------------------------------------------------
// Edges: shapes at large coordinates, truncated maps, maps that expand to millions of triangles,
// grids with their guards off.

/// Random shapes of every kind at every magnitude the format allows (1e0 to 1e15), with rays
/// towards them from far away (capsules' half along their axis), and the capsule whose hit a float
/// closest-point test lost at 1e12: `simulate` at query=shapes must agree with the ground truth in
/// every structure (exit 1 is a disagreement).
rcb::Recording shapes_at_every_scale() {
    rcb::Random r(rcb::mix_seed(9, 1));
    rcb::Recording rec;
    rec.meta = R"({"generator": "hostile_test shapes_at_every_scale"})";
    rec.frames.resize(1);
    auto unit = [&] {
        const rcb::Vec3d d{r.normal(), r.normal(), r.normal()};
        return d * (1 / std::sqrt(rcb::dot(d, d) + 1e-300));
    };
    rcb::Uid uid = 0;
    for (int e = 0; e <= 15; ++e) {
        const double scale = std::pow(10.0, e);
        for (int i = 0; i < 16; ++i) {
            rcb::Vec3d c;
            for (int a = 0; a < 3; ++a) c[a] = (r.below(2) ? 1 : -1) * scale * r.uniform(0.2, 0.4);
            const double size = r.log_uniform(1e-5, 0.1) * scale;
            const rcb::Vec3d u = unit();
            rcb::Shape shape;
            switch (i % 4) {
                case 0:
                    shape = rcb::Shape::triangle(c.as<float>(), (c + unit() * size).as<float>(),
                                                 (c + unit() * size).as<float>());
                    break;
                case 1:
                    shape =
                        rcb::Shape::obb(c.as<float>(), (rcb::Vec3d{1, 0.5, 0.25} * size).as<float>(),
                                        {float(r.normal()), float(r.normal()), float(r.normal()), float(r.normal())});
                    break;
                case 2:
                    shape = rcb::Shape::sphere(c.as<float>(), float(size));
                    break;
                default:
                    shape = rcb::Shape::capsule(c.as<float>(), (c + u * size).as<float>(),
                                                float(size * r.log_uniform(1e-4, 1)));
            }
            rec.initial.push_back(rcb::shaped_object(uid++, shape));
            for (int k = 0; k < 4; ++k) {
                const rcb::Vec3d target = c + unit() * (size * r.uniform(0, 1.5));
                const rcb::Vec3d dir = i % 4 == 3 && k % 2 ? u + unit() * 1e-3 : unit();
                const rcb::Vec3d from = target - dir * (scale * r.uniform(0.2, 0.4));
                rec.frames[0].rays.push_back(
                    {from.as<float>(), (from + (target - from) * r.uniform(0.5, 2)).as<float>()});
            }
        }
    }
    const rcb::Shape thick = rcb::Shape::capsule({8.33427014e11f, 9.31151806e11f, 1.15502337e12f},
                                                 {7.44215675e11f, 8.41504927e11f, 1.12235521e12f}, 1e10f);
    rec.initial.push_back(rcb::shaped_object(uid++, thick));
    rec.frames[0].rays.push_back(
        {{7.46387407e11f, 8.36942627e11f, 1.11675402e12f}, {7.4635667e11f, 8.36911718e11f, 1.11674269e12f}});
    return rec;
}

TEST_F(Hostile, EdgesShapesAtEveryScaleInEveryStructure) {
    rcb::write_recording(shapes_at_every_scale(), (work_ / "scales.rcbscene").string());
    bases_["scales.rcbscene"] = read_bytes(work_ / "scales.rcbscene");
    for (const char* s : {"bf", "ug", "hg", "dbvh", "lbvh", "wbvh", "embree", "bullet_dbvt"})
        check("edges: shapes at every scale",
              {{"simulate", "--scene", "scales.rcbscene", "--structure", s, "--param", "query=shapes"},
               {"scales.rcbscene"},
               {},
               {},
               false,
               std::string("query=shapes in ") + s});
}

/// The fuzz seed map cut at every length past its header: refused in both modes (brushes mode
/// reads no lump after 9 and accepted maps cut there), naming the lump.
TEST_F(Hostile, EdgesTruncatedMapsInEveryMode) {
    ASSERT_NO_FATAL_FAILURE(make_bsp());
    const std::string bsp = bases_["tiny.bsp"];
    const std::size_t header = 8 + 17 * 8;
    const std::size_t step = std::max<std::size_t>(1, (bsp.size() - header) / std::size_t(mutants(40)));
    for (std::size_t size = header; size < bsp.size(); size += step) {
        const std::string f = input("cut", ".bsp", bsp.substr(0, size));
        for (const char* mode : {"brushes", "triangles"}) {
            const std::string out = fresh("imported", ".rcbscene");
            check("edges: truncated map",
                  {{"scene", "import", f, "--bsp-mode", mode, "--frames", "1", "--rays", "8", "-o", out},
                   {f},
                   {out},
                   {f},
                   true,
                   "cut to " + std::to_string(size) + " of " + std::to_string(bsp.size()) + " bytes"});
        }
        done(f);
    }
}

/// A small map whose patches all name one 100x100 grid: 10 million triangles, under the object
/// limit, refused by triangles mode's budget at once (it took 17-23 s); the budget as an option.
TEST_F(Hostile, EdgesMapsExpandingToMillionsOfTriangles) {
    ASSERT_NO_FATAL_FAILURE(make_bsp());
    auto i32 = [](std::string& b, std::int32_t v) { b.append(reinterpret_cast<const char*>(&v), 4); };
    auto f32 = [&](std::string& b, float v) {
        std::int32_t i;
        std::memcpy(&i, &v, 4);
        i32(b, i);
    };
    std::array<std::string, 17> lump;
    for (int y = 0; y < 100; ++y)
        for (int x = 0; x < 100; ++x) {
            f32(lump[10], float(x)), f32(lump[10], float(y)), f32(lump[10], 0);
            for (int k = 0; k < 7; ++k) f32(lump[10], 0);
            i32(lump[10], -1);
        }
    for (int s = 0; s < 510; ++s) {  // patch surfaces (type 2) of the whole grid
        for (std::int32_t v : {0, -1, 2, 0, 100 * 100, 0, 0, 0, 0, 0, 0, 0}) i32(lump[13], v);
        for (int k = 0; k < 12; ++k) f32(lump[13], 0);
        i32(lump[13], 100), i32(lump[13], 100);
    }
    std::string map = "IBSP";
    i32(map, 46);
    std::int32_t offset = 8 + 17 * 8;
    for (const std::string& l : lump)
        i32(map, offset), i32(map, std::int32_t(l.size())), offset += std::int32_t(l.size());
    for (const std::string& l : lump) map += l;
    base("bomb.bsp", map);
    std::vector<Case> cases = {
        {{"scene", "import", "bomb.bsp", "--bsp-mode", "triangles", "--frames", "1", "--rays", "8", "-o", "b.rcbscene"},
         {"bomb.bsp"},
         {"b.rcbscene"},
         {},
         true,
         "10 million triangles from shared patches"},
        {{"scene", "import", "tiny.bsp", "--bsp-mode", "triangles", "--bsp-max-triangles", "1", "-o", "t.rcbscene"},
         {"tiny.bsp"},
         {"t.rcbscene"},
         {},
         true,
         "a budget of one triangle"},
        {{"scene", "import", "tiny.bsp", "--bsp-mode", "triangles", "--bsp-max-triangles", "0", "-o", "t.rcbscene"},
         {"--bsp-max-triangles"},
         {"t.rcbscene"},
         {},
         true,
         "a budget of zero"},
        {{"scene", "import", "tiny.bsp", "--bsp-mode", "triangles", "--bsp-max-triangles", "1e99", "-o", "t.rcbscene"},
         {"--bsp-max-triangles"},
         {"t.rcbscene"},
         {},
         true,
         "a budget beyond the object limit"},
        {{"scene", "import", "tiny.bsp", "--bsp-mode", "triangles", "--bsp-max-triangles", "1000", "-o", "t.rcbscene"},
         {},
         {"t.rcbscene"},
         {},
         false,
         "a budget the map fits"},
    };
    for (const Case& c : cases) check("edges: triangle budget", c);
}

/// A uniform grid with its guards off on identical boxes is unbounded by design (the guards are
/// there to be measured); it finishes on a small scene and says in its stats which guard would
/// have fired.
TEST_F(Hostile, EdgesGridsWithTheirGuardsOffSaySo) {
    setup_run({"scene", "gen", "--preset", "identical-s", "--frames", "2", "--rays", "16", "-o", "same.rcbscene"},
              {"same.rcbscene"});
    for (const char* s : {"ug", "hg"}) {
        const std::vector<std::string> args = {
            "simulate", "--scene",     "same.rcbscene", "--structure",         s,
            "--param",  "max_cells=0", "--param",       "outlier_guard=false", "--json"};
        check("edges: guards off", {args, {}, {}, {}, false, std::string("guards off in ") + s});
        std::vector<std::string> argv{RCBENCH_BINARY};
        argv.insert(argv.end(), args.begin(), args.end());
        test::RunOptions o;
        o.cwd = work_.string();
        o.cpu_seconds = time_limit();
        o.timeout_seconds = wall_limit();
        const test::Outcome out = test::run_process(argv, o);
        ASSERT_EQ(out.code, 0) << out.err;
        const json j = json::parse(out.out.substr(0, out.out.find('\n')));
        ASSERT_TRUE(j.contains("stats")) << out.out.substr(0, 300);
        EXPECT_NE(j["stats"].dump().find("\"guards_off\":{\"max_cells\":"), std::string::npos) << s;
    }
}

}  // namespace
