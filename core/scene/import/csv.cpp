#include "core/scene/import/csv.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <unordered_map>

#include "core/base/error.h"
#include "core/scene/recording_io.h"

namespace rcb {
namespace {

std::string read_text(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path + ": cannot open (" + std::strerror(errno) + ")");
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
    return s;
}

template <typename T>
bool parse_number(std::string_view s, T& out) {
    auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && end == s.data() + s.size();
}

/// A coordinate's text as a float, and as a double for the range check: text beyond float's range
/// ("1e39", "1e-50") is a number too, reported against the coordinate limits rather than as "not a
/// number" (`out_of_range` set; messages show the text as written, which may be beyond double's
/// range too).
bool parse_coordinate(std::string_view s, float& out, double& wide, bool& out_of_range) {
    auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    out_of_range = false;
    if (end != s.data() + s.size()) return false;
    if (ec == std::errc()) {
        wide = out;
        return true;
    }
    if (ec != std::errc::result_out_of_range) return false;
    out_of_range = true;
    wide = std::strtod(std::string(s).c_str(), nullptr);  // ±HUGE_VAL or 0 beyond double's range
    if (wide == 0) wide = std::copysign(std::numeric_limits<double>::denorm_min(), s.front() == '-' ? -1.0 : 1.0);
    out = 0;  // never used: the value is beyond the coordinate limits either way
    return true;
}

/// Calls `row(fields, line_number)` for each data line with exactly `columns.size()` fields. The
/// first data line is a header when its first field is not a number.
template <typename Row>
void for_each_row(const std::string& text, const std::string& name, const std::vector<const char*>& columns,
                  Row&& row) {
    const std::string expected = join(columns, ",");
    std::size_t line_no = 0, pos = 0;
    // A UTF-8 byte-order mark (spreadsheet exports write one) is not part of the first field.
    if (text.compare(0, 3, "\xEF\xBB\xBF") == 0) pos = 3;
    bool first_data = true;
    std::vector<std::string_view> fields;
    while (pos < text.size()) {
        std::size_t nl = text.find('\n', pos);
        std::string_view line(text.data() + pos, (nl == std::string::npos ? text.size() : nl) - pos);
        pos = nl == std::string::npos ? text.size() : nl + 1;
        ++line_no;
        line = trim(line);
        if (line.empty() || line.front() == '#') continue;
        fields.clear();
        std::size_t start = 0;
        for (;;) {
            std::size_t comma = line.find(',', start);
            fields.push_back(
                trim(line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start)));
            if (comma == std::string_view::npos) break;
            start = comma + 1;
        }
        const std::string where = name + ":" + std::to_string(line_no);
        double probe;
        if (first_data && !parse_number(fields[0], probe) && fields[0] != "nan" && fields[0] != "inf") {
            first_data = false;
            if (fields.size() != columns.size())
                throw InputError(where + ": header has " + std::to_string(fields.size()) + " columns, expected " +
                                 std::to_string(columns.size()) + " (" + expected + ")");
            continue;
        }
        first_data = false;
        if (fields.size() != columns.size())
            throw InputError(where + ": expected " + std::to_string(columns.size()) + " fields (" + expected +
                             "), got " + std::to_string(fields.size()));
        row(fields, where, line_no);
    }
}

/// Field i as a coordinate, checked against the coordinate limit (recording_io.h) here so the
/// message names the field (`what`, "uid 7: " or "", goes before it); non-finite values are left
/// to box_problem / segment_problem.
float field_float(const std::vector<std::string_view>& fields, std::size_t i, const std::vector<const char*>& columns,
                  const std::string& where, const std::string& what) {
    float v;
    double wide;
    bool out_of_range;
    auto field = [&] { return "field " + std::to_string(i + 1) + " (" + columns[i] + ")"; };
    if (!parse_coordinate(fields[i], v, wide, out_of_range))
        throw InputError(where + ": " + field() + ": " + quoted_excerpt(fields[i]) + " is not a number");
    if (std::isfinite(wide) || out_of_range)
        if (const std::string problem = coordinate_problem(wide, fields[i]); !problem.empty())
            throw InputError(where + ": " + what + field() + ": " + problem);
    return v;
}

}  // namespace

std::vector<Object> parse_boxes_csv(const std::string& text, const std::string& name) {
    static const std::vector<const char*> columns = {"uid", "minx", "miny", "minz", "maxx", "maxy", "maxz"};
    std::vector<Object> objects;
    std::unordered_map<Uid, std::size_t> first_line;
    for_each_row(text, name, columns,
                 [&](const std::vector<std::string_view>& f, const std::string& where, std::size_t line) {
                     Object o;
                     if (!parse_number(f[0], o.uid))
                         throw InputError(where + ": field 1 (uid): " + quoted_excerpt(f[0]) +
                                          " is not an integer in 0..4294967295");
                     const std::string what = "uid " + std::to_string(o.uid) + ": ";
                     for (int a = 0; a < 3; ++a) {
                         o.box.min[a] = field_float(f, 1 + a, columns, where, what);
                         o.box.max[a] = field_float(f, 4 + a, columns, where, what);
                     }
                     check_object(o, where);
                     auto [it, fresh] = first_line.emplace(o.uid, line);
                     if (!fresh)
                         throw InputError(where + ": duplicate uid " + std::to_string(o.uid) + " (first on line " +
                                          std::to_string(it->second) + ")");
                     objects.push_back(o);
                 });
    return objects;
}

std::vector<Segment> parse_rays_csv(const std::string& text, const std::string& name) {
    static const std::vector<const char*> columns = {"x0", "y0", "z0", "x1", "y1", "z1"};
    std::vector<Segment> rays;
    for_each_row(text, name, columns,
                 [&](const std::vector<std::string_view>& f, const std::string& where, std::size_t) {
                     Segment s;
                     for (int a = 0; a < 3; ++a) {
                         s.p0[a] = field_float(f, a, columns, where, "");
                         s.p1[a] = field_float(f, 3 + a, columns, where, "");
                     }
                     const std::string problem = segment_problem(s);
                     if (!problem.empty()) throw InputError(where + ": " + problem);
                     rays.push_back(s);
                 });
    return rays;
}

std::vector<Object> read_boxes_csv(const std::string& path) { return parse_boxes_csv(read_text(path), path); }
std::vector<Segment> read_rays_csv(const std::string& path) { return parse_rays_csv(read_text(path), path); }

}  // namespace rcb
