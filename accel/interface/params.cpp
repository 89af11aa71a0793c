#include "accel/interface/params.h"

#include "core/base/json_input.h"

#include <cmath>
#include <sstream>

namespace rcb {

namespace {
std::string format_number(double v) {
    std::ostringstream s;
    s.precision(12);
    s << v;
    return s.str();
}
}  // namespace

std::string join_path(std::string_view path, std::string_view key) {
    if (path.empty()) return std::string(key);
    return std::string(path) + "." + std::string(key);
}

nlohmann::json ParamSpec::to_json() const {
    static const char* kinds[] = {"integer", "real", "boolean", "choice"};
    nlohmann::json j = {{"name", name},
                        {"type", kinds[static_cast<int>(kind)]},
                        {"default", default_value},
                        {"doc", doc},
                        {"tunable", tunable}};
    if (kind == ParamKind::integer || kind == ParamKind::real) {
        j["min"] = lo;
        j["max"] = hi;
        j["log_scale"] = log_scale;
    }
    if (kind == ParamKind::choice) j["choices"] = choices;
    return j;
}

std::string ParamSpec::expectation() const {
    switch (kind) {
        case ParamKind::integer:
            return "an integer in " + format_number(lo) + ".." + format_number(hi);
        case ParamKind::real:
            return "a number in " + format_number(lo) + ".." + format_number(hi);
        case ParamKind::boolean:
            return "true or false";
        case ParamKind::choice: {
            std::string s = "one of ";
            for (std::size_t i = 0; i < choices.size(); ++i) s += (i ? ", " : "") + choices[i];
            return s;
        }
    }
    return {};
}

void check_param(const ParamSpec& spec, const nlohmann::json& v, const std::string& path) {
    bool ok = false;
    switch (spec.kind) {
        case ParamKind::integer:
            ok = (v.is_number_integer() || v.is_number_unsigned()) && v.get<double>() >= spec.lo &&
                 v.get<double>() <= spec.hi;
            break;
        case ParamKind::real:
            ok = v.is_number() && std::isfinite(v.get<double>()) && v.get<double>() >= spec.lo &&
                 v.get<double>() <= spec.hi;
            break;
        case ParamKind::boolean:
            ok = v.is_boolean();
            break;
        case ParamKind::choice:
            ok = v.is_string() &&
                 std::find(spec.choices.begin(), spec.choices.end(), v.get<std::string>()) != spec.choices.end();
            break;
    }
    if (!ok) throw InputError(path + ": expected " + spec.expectation() + ", got " + json_excerpt(v));
}

void check_params(const std::vector<ParamSpec>& specs, const nlohmann::json& params, const std::string& path,
                  std::string_view owner) {
    if (params.is_null()) return;  // no parameters given: all defaults
    if (!params.is_object())
        throw InputError((path.empty() ? std::string("params") : path) + ": expected an object of parameters, got " +
                         json_excerpt(params));
    for (const auto& [key, value] : params.items()) {
        auto spec =
            std::find_if(specs.begin(), specs.end(), [&, &key = key](const ParamSpec& s) { return s.name == key; });
        if (spec == specs.end()) {
            const std::string known = join(specs, ", ", &ParamSpec::name);
            throw InputError(join_path(path, key) + ": unknown parameter of " + std::string(owner) + " (" +
                             (known.empty() ? std::string("it takes none") : "known: " + known) + ")");
        }
        check_param(*spec, value, join_path(path, key));
    }
}

std::vector<std::string> detail::split_choices(const char* choices) {
    std::vector<std::string> out;
    std::string current;
    for (const char* c = choices; *c; ++c) {
        if (*c == ',') {
            out.push_back(current);
            current.clear();
        } else {
            current += *c;
        }
    }
    if (!current.empty()) out.push_back(current);
    return out;
}

std::pair<std::string, nlohmann::json> parse_key_value(const std::string& argument) {
    auto eq = argument.find('=');
    if (eq == std::string::npos || eq == 0) throw InputError("--param " + argument + ": expected key=value");
    std::string key = argument.substr(0, eq);
    std::string text = argument.substr(eq + 1);
    nlohmann::json value = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
    if (value.is_discarded() || !(value.is_number() || value.is_boolean())) value = text;
    return {key, value};
}

}  // namespace rcb
