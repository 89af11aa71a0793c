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
