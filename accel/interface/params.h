#pragma once
/// Typed structure parameters, described once and used everywhere.
///
/// A structure's `Params` is a plain struct with documented defaults plus a `fields()` list that
/// names each field with its range. From that one list come: JSON in (validated, unknown keys
/// refused) and out, and the `ParamSpec`s the registry publishes so that the runner can validate
/// experiment files and the tuner can know its search space without knowing the structure.
///
///     struct Params {
///         double density = 2.0;
///         int max_depth = 4;
///         static constexpr auto fields() {
///             return std::tuple{
///                 Field{"density", &Params::density, 0.01, 64.0, "objects per cell (eq. 4.1)"},
///                 Field{"max_depth", &Params::max_depth, 1, 8, "levels below the top grid"}};
///         }
///     };

#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/base/error.h"

namespace rcb {

enum class ParamKind { integer, real, boolean, choice };

/// What the runner and tuner know of a parameter.
struct ParamSpec {
    std::string name;
    ParamKind kind = ParamKind::real;
    double lo = 0, hi = 0;             ///< inclusive range (integer and real)
    std::vector<std::string> choices;  ///< allowed values (choice)
    nlohmann::json default_value;
    std::string doc;
    bool tunable = false;    ///< the tuner may search it
    bool log_scale = false;  ///< search it on a log scale (spans orders of magnitude)
    /// false: complete parameters leave it out while it has its default, so adding the parameter
    /// to every structure does not change the recorded parameters of existing configurations.
    bool recorded_when_default = true;

    nlohmann::json to_json() const;
    /// "an integer in 1..16", "a number in 0.01..64", "true or false", "one of low, medium".
    std::string expectation() const;
};

/// What a field is beyond its name, range and documentation, by name: one of the constants below
/// (`Field{"bins", &P::bins, 2, 256, "SAH bins", kLogScale}`), `choices("low,medium")`, or
/// designated initialisers (`FieldOptions{.tunable = false, .log_scale = true}`).
struct FieldOptions {
    bool tunable = true;     ///< ParamSpec::tunable
    bool log_scale = false;  ///< ParamSpec::log_scale
    /// For std::string fields: the allowed values, comma-separated.
    const char* choices = "";
    bool recorded_when_default = true;  ///< ParamSpec::recorded_when_default
};

/// A field the tuner leaves alone (guards, thread counts, switches kept for measuring).
inline constexpr FieldOptions kNotTuned{.tunable = false};
/// A tunable field searched on a log scale (it spans orders of magnitude).
inline constexpr FieldOptions kLogScale{.log_scale = true};
/// A field the tuner leaves alone that complete parameters leave out while it has its default.
inline constexpr FieldOptions kNotTunedDefaultUnrecorded{.tunable = false, .recorded_when_default = false};
/// A tunable std::string field with these allowed values (comma-separated).
constexpr FieldOptions choices(const char* allowed) { return FieldOptions{.choices = allowed}; }

/// One field of a Params struct.
template <class P, class T>
struct Field {
    const char* name;
    T P::*member;
    double lo;
    double hi;
    const char* doc;
    FieldOptions options = {};
};

// The deduction spelled out (clang 14, the fuzzing build, has no aggregate CTAD).
template <class P, class T>
Field(const char*, T P::*, double, double, const char*) -> Field<P, T>;
template <class P, class T>
Field(const char*, T P::*, double, double, const char*, FieldOptions) -> Field<P, T>;

/// Joins a JSON path and a key for messages: ("structures[2].params", "max_depth").
std::string join_path(std::string_view path, std::string_view key);

/// Checks `value` against `spec`; throws InputError "<path>: expected <expectation>, got <value>".
void check_param(const ParamSpec& spec, const nlohmann::json& value, const std::string& path);

/// Checks a whole parameter object: an object, no unknown keys (named with the known ones), every
/// value in range. `owner` names the structure in messages.
void check_params(const std::vector<ParamSpec>& specs, const nlohmann::json& params, const std::string& path,
                  std::string_view owner);

namespace detail {
template <class T>
constexpr ParamKind kind_of() {
    if constexpr (std::is_same_v<T, bool>)
        return ParamKind::boolean;
    else if constexpr (std::is_integral_v<T>)
        return ParamKind::integer;
    else if constexpr (std::is_floating_point_v<T>)
        return ParamKind::real;
    else
        return ParamKind::choice;
}
std::vector<std::string> split_choices(const char* choices);
}  // namespace detail

template <class P>
std::vector<ParamSpec> param_specs() {
    std::vector<ParamSpec> specs;
    const P defaults{};
    std::apply(
        [&](auto... field) {
            (specs.push_back(ParamSpec{
                 field.name, detail::kind_of<std::remove_cvref_t<decltype(defaults.*(field.member))>>(), field.lo,
                 field.hi, detail::split_choices(field.options.choices), nlohmann::json(defaults.*(field.member)),
                 field.doc, field.options.tunable, field.options.log_scale, field.options.recorded_when_default}),
             ...);
        },
        P::fields());
    return specs;
}

template <class P>
nlohmann::json params_to_json(const P& p) {
    nlohmann::json j = nlohmann::json::object();
    std::apply([&](auto... field) { ((j[field.name] = p.*(field.member)), ...); }, P::fields());
    return j;
}

/// Defaults overridden by the keys of `j`, after check_params.
template <class P>
P params_from_json(const nlohmann::json& j, const std::string& path, std::string_view owner) {
    check_params(param_specs<P>(), j, path, owner);
    P p{};
    if (j.is_null()) return p;
    std::apply(
        [&](auto... field) {
            ((j.contains(field.name)
                  ? void(p.*(field.member) =
                             j.at(field.name).template get<std::remove_cvref_t<decltype(p.*(field.member))>>())
                  : void()),
             ...);
        },
        P::fields());
    return p;
}

/// A choice parameter's text as the enum whose enumerators list `choices` (comma-separated, as in
/// FieldOptions::choices) in order: parsed once when a structure is configured, so that hot paths
/// compare enums, while the text stays what users write and what is stored. Throws InputError
/// "<param>: expected one of …, got …" for text outside the choices (JSON input is checked before).
template <class E>
E parse_choice(const char* choices, std::string_view value, std::string_view param) {
    const std::vector<std::string> all = detail::split_choices(choices);
    for (std::size_t i = 0; i < all.size(); ++i)
        if (all[i] == value) return static_cast<E>(i);
    ParamSpec spec;
    spec.kind = ParamKind::choice;
    spec.choices = all;
    throw InputError(std::string(param) + ": expected " + spec.expectation() + ", got \"" + std::string(value) + "\"");
}

/// Parses a command-line `key=value` into (key, JSON value): numbers and true/false as such,
/// anything else as a string. Throws InputError naming the argument when there is no '='.
std::pair<std::string, nlohmann::json> parse_key_value(const std::string& argument);

}  // namespace rcb
