#pragma once
/// JSON from users (experiment and tuning files, --param values, a recording's META): parsed with a
/// nesting limit, and quoted in error messages as a short excerpt. nlohmann::json parses iteratively
/// but dumps recursively, so a deeply nested value would overflow the stack when an error message
/// prints it; and a message must stay one readable line even when the value is megabytes long.

#include <cstddef>
#include <string>

#include <nlohmann/json.hpp>

namespace rcb {

/// Deepest nesting of arrays and objects accepted in a user's JSON (rcbench's own files need 6).
inline constexpr int kMaxJsonDepth = 64;

/// Parses `text`; InputError naming `name` when it is not JSON, nests deeper than kMaxJsonDepth, or
/// holds a number outside double's range (1e999).
nlohmann::json parse_json_document(const std::string& text, const std::string& name);

/// `value` as compact JSON for a message: at most `max_chars` characters (then "..."), invalid
/// UTF-8 replaced, never throws.
std::string json_excerpt(const nlohmann::json& value, std::size_t max_chars = 80);

}  // namespace rcb
