#include "allocation_counter.hpp"

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdlib>
#include <vector>

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
std::atomic<long> g_allocated_bytes{0};
void count_allocation(std::size_t bytes) {
  if (g_counting.load(std::memory_order_relaxed)) {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    g_allocated_bytes.fetch_add(static_cast<long>(bytes), std::memory_order_relaxed);
  }
}
}  // namespace

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
// Sanitizers own malloc; they report every allocation to this hook instead. (Declared here: GCC
// does not install the sanitizer interface headers.)
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*,
                                                                             std::size_t),
                                                         void (*free_hook)(const volatile void*));
extern "C" void laserline_malloc_hook(const volatile void*, std::size_t size) {
  count_allocation(size);
}
extern "C" void laserline_free_hook(const volatile void*) {}
static const int kHooksInstalled =
    __sanitizer_install_malloc_and_free_hooks(laserline_malloc_hook, laserline_free_hook);
#else
// glibc: interpose the C allocator, which operator new, LCM and glib all end up in.
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void* malloc(std::size_t size) {
  count_allocation(size);
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) {
  count_allocation(n * size);
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) {
  count_allocation(size);
  return __libc_realloc(p, size);
}
void* memalign(std::size_t alignment, std::size_t size) {
  count_allocation(size);
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) {
  count_allocation(size);
  *out = __libc_memalign(alignment, size);
  return *out != nullptr ? 0 : ENOMEM;
}
void* aligned_alloc(std::size_t alignment, std::size_t size) {
  count_allocation(size);
  return __libc_memalign(alignment, size);
}
}
#endif

namespace laserline::testing {

void start_counting_allocations() {
  g_allocations = 0;
  g_allocated_bytes = 0;
  g_counting = true;
}

Allocations stop_counting_allocations() {
  g_counting = false;
  return {g_allocations.exchange(0), g_allocated_bytes.exchange(0)};
}

bool allocation_counter_works() {
  start_counting_allocations();
  {
    auto* probe = new std::vector<int>(100);
    void* c_probe = std::malloc(64);
    std::free(c_probe);
    delete probe;
  }
  return stop_counting_allocations().count >= 2;
}

}  // namespace laserline::testing
