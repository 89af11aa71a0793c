#pragma once
/// Bytes a container holds on the heap, for a structure's memory_bytes() (accel/interface/structure.h):
/// capacity, not size, since that is what the process pays. One call sums several containers:
///
///     std::size_t memory_bytes() const override { return sizeof(*this) + rcb::heap_bytes(list_, index_); }
///
/// A hash map is counted as libstdc++ lays it out (hashtable.h, _Hashtable and _Hash_node): one
/// pointer per bucket, and per entry a node holding the next pointer and the key-value pair (the
/// hash is cached in the node only for keys whose hash is not trivial; integer keys' is).

#include <cstddef>
#include <unordered_map>
#include <utility>
#include <vector>

namespace rcb {

template <class T, class Alloc>
std::size_t heap_bytes(const std::vector<T, Alloc>& v) {
    return v.capacity() * sizeof(T);
}

template <class K, class V, class Hash, class Eq, class Alloc>
std::size_t heap_bytes(const std::unordered_map<K, V, Hash, Eq, Alloc>& m) {
    return m.bucket_count() * sizeof(void*) + m.size() * (sizeof(void*) + sizeof(std::pair<const K, V>));
}

template <class... Containers>
requires(sizeof...(Containers) != 1) std::size_t heap_bytes(const Containers&... containers) {
    return (std::size_t(0) + ... + heap_bytes(containers));
}

}  // namespace rcb
