#pragma once
// Counts the allocations made by the calling thread while a ThreadAllocationCount is alive, for
// tests proving that a frame-path call allocates nothing. Include in exactly one file of a test
// executable: it interposes the C allocator (or, in sanitized builds, installs the sanitizers'
// allocation hook), which operator new and every library end up in.
#include <atomic>
#include <cstddef>

namespace laserline::test {

inline thread_local bool t_count_allocations = false;
inline std::atomic<long> g_thread_allocations{0};

inline void count_thread_allocation() {
  if (t_count_allocations) g_thread_allocations.fetch_add(1, std::memory_order_relaxed);
}

// Counts this thread's allocations from construction to count().
class ThreadAllocationCount {
 public:
  ThreadAllocationCount() {
    g_thread_allocations.store(0);
    t_count_allocations = true;
  }
  ~ThreadAllocationCount() { t_count_allocations = false; }
  long count() const { return g_thread_allocations.load(); }
};

}  // namespace laserline::test

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*,
                                                                             std::size_t),
                                                         void (*free_hook)(const volatile void*));
extern "C" void laserline_thread_malloc_hook(const volatile void*, std::size_t) {
  laserline::test::count_thread_allocation();
}
extern "C" void laserline_thread_free_hook(const volatile void*) {}
static const int kThreadAllocationHooks = __sanitizer_install_malloc_and_free_hooks(
    laserline_thread_malloc_hook, laserline_thread_free_hook);
#else
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* malloc(std::size_t size) {
  laserline::test::count_thread_allocation();
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) {
  laserline::test::count_thread_allocation();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) {
  laserline::test::count_thread_allocation();
  return __libc_realloc(p, size);
}
}
#endif
