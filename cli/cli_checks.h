#pragma once
/// Checks for numeric command-line options that CLI11's own conversions let through: NaN passes
/// CLI::Range (every comparison with NaN is false), and an unsigned option takes "-1" or a number
/// beyond 2^64 by wrapping or saturating. Both would reach the generators as silent nonsense.

#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <limits>
#include <string>
#include <type_traits>

#include <CLI/CLI.hpp>

#include "analysis/repetitions.h"
#include "runner/experiment.h"

namespace rcb {

/// A finite number in [lo, hi].
inline CLI::Validator finite_range(double lo, double hi) {
    return CLI::Validator(
        [lo, hi](std::string& text) -> std::string {
            double v = 0;
            const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v) || v < lo || v > hi)
                return "expected a number in " + CLI::detail::to_string(lo) + ".." + CLI::detail::to_string(hi) +
                       ", got " + text;
            return {};
        },
        "NUMBER in " + CLI::detail::to_string(lo) + ".." + CLI::detail::to_string(hi));
}

/// Decimal digits only (no sign, no hex), in [lo, hi].
inline CLI::Validator whole_number(std::uint64_t lo = 0, std::uint64_t hi = std::numeric_limits<std::uint64_t>::max()) {
    return CLI::Validator(
        [lo, hi](std::string& text) -> std::string {
            std::uint64_t v = 0;
            const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            if (text.empty() || ec != std::errc() || end != text.data() + text.size() || v < lo || v > hi)
                return "expected a whole number in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " + text;
            return {};
        },
        "UINT");
}

/// An existing regular file to read: not empty, not a folder, and not a device or pipe such as
/// /dev/zero, whose reading would never end.
inline CLI::Validator input_file() {
    return CLI::Validator(
        [](std::string& path) -> std::string {
            if (path.empty()) return "expected a file name, got an empty one";
            std::error_code ec;
            const std::filesystem::file_status st = std::filesystem::status(path, ec);
            if (!std::filesystem::exists(st)) return "no such file: " + path;
            if (std::filesystem::is_directory(st)) return path + " is a folder, not a file";
            if (!std::filesystem::is_regular_file(st)) return path + " is not a regular file";
            return {};
        },
        "FILE");
}

/// A run id as the database numbers them: 1 and up. An explicit 0 is refused, not read as "the
/// newest run" (what leaving the option out means).
inline CLI::Validator run_id() { return whole_number(1, std::uint64_t(std::numeric_limits<std::int64_t>::max())); }

/// A non-empty text (names, folders).
inline CLI::Validator non_empty() {
    return CLI::Validator([](std::string& text) -> std::string { return text.empty() ? "must not be empty" : ""; }, "");
}

/// An option's old name, kept as an alias for one release: --help says it is deprecated, it sets
/// what `new_name` sets and, once its value has passed the checks, says so on stderr in one line
/// ("rcbench: --validate is deprecated; use --check"). A flag with `T` bool, else an option with a
/// value of type T.
template <class T>
CLI::Option* add_deprecated_alias(CLI::App* cmd, const std::string& old_name, const std::string& new_name, T& target) {
    const auto say = [old_name, new_name] {
        std::cerr << "rcbench: " << old_name << " is deprecated; use " << new_name << '\n';
    };
    const std::string help = "Deprecated: use " + new_name;
    if constexpr (std::is_same_v<T, bool>)
        return cmd->add_flag_callback(
            old_name, [&target, say] { target = true, say(); }, help);
    else
        return cmd->add_option_function<T>(
            old_name, [&target, say](const T& v) { target = v, say(); }, help);
}

/// The first old key that a file's scenes use (SceneSpec::deprecated), as one line on stderr
/// naming the file; whether there was one.
inline bool say_deprecated_keys(const std::string& file, const std::vector<SceneSpec>& scenes) {
    for (const SceneSpec& s : scenes)
        if (!s.deprecated.empty()) {
            std::cerr << "rcbench: " << file << ": " << s.deprecated << '\n';
            return true;
        }
    return false;
}

/// `--repetitions fastest-cast|fastest|median`: what stands for a cell's repetitions (analysis/repetitions.h).
inline CLI::Option* add_repetitions_option(CLI::App* cmd, OverRepetitions& how) {
    return cmd
        ->add_option_function<std::string>(
            "--repetitions", [&how](const std::string& name) { how = parse_repetitions(name).value(); },
            "What stands for a cell's repetitions: 'fastest-cast' (the default), each frame's fastest ray cast "
            "(another process only ever adds time) and its median update over them (the cache state an update "
            "starts in also takes time away); 'fastest', each frame's fastest of both; or 'median', every "
            "repetition as measured")
        ->check(CLI::IsMember(repetitions_names()))
        ->default_str(repetitions_name(OverRepetitions::fastest_cast));
}

}  // namespace rcb
