// Scratch storage that a vector's growth does not zero-fill.
#pragma once

#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace lic {

/// std::allocator whose value-less construct() default-initialises: growing a vector of floats
/// leaves the new elements unset instead of zero-filling them. For large scratch that is always
/// written before it is read: the engines' per-brick sums (zeroed a block at a time when first
/// reached) and their output blocks (written whole); a comet loop's are tens of MiB per thread.
template<typename T>
struct DefaultInitAllocator : std::allocator<T>
{
    using value_type = T;
    template<typename U>
    struct rebind
    {
        using other = DefaultInitAllocator<U>;
    };
    DefaultInitAllocator() = default;
    template<typename U>
    DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept
    {
    }
    template<typename U>
    void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>)
    {
        ::new (static_cast<void*>(p)) U;
    }
    template<typename U, typename... Args>
    void construct(U* p, Args&&... args)
    {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

/// A vector whose resize() leaves new elements uninitialised (see DefaultInitAllocator); assign()
/// and resize(n, value) still set them.
template<typename T>
using ScratchVector = std::vector<T, DefaultInitAllocator<T>>;

} // namespace lic
