#pragma once
/// Errors carry their context (file, line or JSON path, frame, uid) in the message, so the CLI can
/// print one line. `InputError` is the user's input being wrong (exit 2); anything else is a
/// failure of ours or of the machine (exit 1).

#include <functional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace rcb {

class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// User text (a CSV field, a file's bytes, a name from JSON) fit for a one-line message: in single
/// quotes, every byte outside printable ASCII written as \xNN (so a BOM, a tab or a newline cannot
/// hide or break the line), and cut to at most `max` characters between the quotes, with "…" after
/// the quote when cut (a 10 MB field must not become a 10 MB message). Escapes are never split.
inline std::string quoted_excerpt(std::string_view text, std::size_t max = 80) {
    static constexpr char hex[] = "0123456789ABCDEF";
    std::string out = "'";
    std::size_t shown = 0, i = 0;
    for (; i < text.size(); ++i) {
        const auto c = static_cast<unsigned char>(text[i]);
        const bool plain = c >= 0x20 && c < 0x7f;
        const std::size_t width = plain ? 1 : 4;
        if (shown + width > max) break;
        if (plain) {
            out += char(c);
        } else {
            out += "\\x";
            out += hex[c >> 4];
            out += hex[c & 15];
        }
        shown += width;
    }
    out += '\'';
    if (i < text.size()) out += "…";
    return out;
}

/// The items' names separated by `sep`, for messages such as "unknown kind 'x' (known: a, b, c)".
template <class Range, class Name = std::identity>
std::string join(const Range& items, std::string_view sep = ", ", Name name = {}) {
    std::string out;
    for (const auto& item : items) {
        if (!out.empty()) out += sep;
        out += std::invoke(name, item);
    }
    return out;
}

}  // namespace rcb
