"""Give memory the program no longer holds back to the operating system.

Planning a large field allocates and frees hundreds of megabytes of arrays;
glibc keeps freed heap pages (its mmap threshold grows after large frees), so
the resident size of a long flight would carry the planner's peak for hours.
``release_freed_memory`` asks the allocator to return them (``malloc_trim``);
elsewhere than glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc


def release_freed_memory() -> bool:
    """Collect garbage and trim the C heap; True when the allocator was asked."""
    gc.collect()
    name = ctypes.util.find_library("c")
    if not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return False
    trim.argtypes = (ctypes.c_size_t,)
    trim(0)
    return True
