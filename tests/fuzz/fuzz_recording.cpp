/// libFuzzer target: the recording reader (core/scene/recording_io.h). The input is a recording file
/// whose section checksums are recomputed first, so that mutations reach the section parsers
/// instead of stopping at the CRC check. Any input must either decode or throw InputError; a
/// decoded recording must encode and decode to itself.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include <zlib.h>

#include "core/base/error.h"
#include "core/scene/recording_io.h"

namespace {

/// Walks the section headers after the 16-byte file header and rewrites each CRC-32 (a payload
/// running past the end is left alone: the reader must report it).
void fix_checksums(std::string& bytes) {
    std::size_t at = 16;
    while (at + 16 <= bytes.size()) {
        std::uint64_t len = 0;
        for (int i = 7; i >= 0; --i) len = (len << 8) | static_cast<unsigned char>(bytes[at + 4 + i]);
        const std::size_t payload = at + 16;
        if (len > bytes.size() - payload) return;
        const std::uint32_t crc =
            std::uint32_t(crc32(0, reinterpret_cast<const Bytef*>(bytes.data() + payload), static_cast<uInt>(len)));
        for (int i = 0; i < 4; ++i) bytes[at + 12 + i] = char((crc >> (8 * i)) & 0xff);
        at = payload + std::size_t(len);
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::string bytes(reinterpret_cast<const char*>(data), size);
    fix_checksums(bytes);
    rcb::Recording r;
    try {
        r = rcb::decode_recording(bytes, "fuzz.rcbscene");
    } catch (const rcb::InputError&) {
        return 0;
    }
    const std::string again = rcb::encode_recording(r);
    if (!(rcb::decode_recording(again, "re-encoded") == r)) std::abort();
    return 0;
}
