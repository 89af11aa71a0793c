#include "runner/binary_identity.h"

#include <elf.h>
#include <link.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <system_error>

#include "runner/experiment.h"

namespace rcb {
namespace {

/// Notes are 4-byte aligned in both ELF classes (the System V ABI's note section; the GNU notes the
/// linker writes follow it).
std::size_t padded(std::size_t n) { return (n + 3) & ~std::size_t(3); }

/// dl_iterate_phdr visits the main program first (glibc's dl_iterate_phdr(3)): its PT_NOTE
/// segments, searched for the build id; returning 1 stops after it.
int main_program_build_id(dl_phdr_info* info, std::size_t, void* out) {
    for (int i = 0; i < info->dlpi_phnum; ++i) {
        const ElfW(Phdr)& ph = info->dlpi_phdr[i];
        if (ph.p_type != PT_NOTE) continue;
        const auto* notes = reinterpret_cast<const unsigned char*>(info->dlpi_addr + ph.p_vaddr);
        std::string id = gnu_build_id(notes, ph.p_memsz);
        if (!id.empty()) {
            *static_cast<std::string*>(out) = std::move(id);
            break;
        }
    }
    return 1;
}

BinaryIdentity identify() {
    BinaryIdentity b;
    std::error_code ec;
    const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
    b.name = ec || exe.filename().empty() ? "unknown" : exe.filename().string();
    dl_iterate_phdr(main_program_build_id, &b.build_id);
    if (b.build_id.empty()) {
        std::ifstream in("/proc/self/exe", std::ios::binary);
        const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
        b.build_id = in.bad() || bytes.empty() ? "unknown" : "fnv-" + stable_hash(bytes);
    }
    return b;
}

}  // namespace

std::string gnu_build_id(const unsigned char* notes, std::size_t size) {
    std::size_t at = 0;
    while (at + sizeof(ElfW(Nhdr)) <= size) {
        ElfW(Nhdr) h;
        std::memcpy(&h, notes + at, sizeof h);
        const std::size_t name_at = at + sizeof h, desc_at = name_at + padded(h.n_namesz);
        if (desc_at > size || h.n_descsz > size - desc_at) break;  // a truncated note ends the search
        if (h.n_type == NT_GNU_BUILD_ID && h.n_namesz == 4 && std::memcmp(notes + name_at, "GNU", 4) == 0 &&
            h.n_descsz > 0) {
            static const char* const kHex = "0123456789abcdef";
            std::string hex;
            for (std::size_t i = 0; i < h.n_descsz; ++i)
                hex += {kHex[notes[desc_at + i] >> 4], kHex[notes[desc_at + i] & 15]};
            return hex;
        }
        at = desc_at + padded(h.n_descsz);
    }
    return {};
}

const BinaryIdentity& this_binary() {
    static const BinaryIdentity identity = identify();
    return identity;
}

}  // namespace rcb
