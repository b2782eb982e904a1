//! The memory routines the compiler calls (`memcpy`, `memset`, `memcmp`
//! and their `__aeabi_*` forms), in place of compiler_builtins' (whose
//! symbols are weak, so these win at link time). Theirs are unrolled for
//! speed and take about 1.9 KB of flash; these copy, fill and compare a
//! byte per step (a word per step where the caller guarantees 4-byte
//! alignment) in a few dozen bytes. The bridge moves at most a few KB per
//! frame, at serial-line rates. The stores are volatile so that the
//! optimiser cannot turn the loops back into calls to these functions, and
//! no routine calls another by its C name (the optimiser takes a call to
//! `memmove` for the built-in and lowers it to `__aeabi_memmove`, which
//! would then call itself).

/// Copies `n` bytes forwards.
///
/// # Safety
/// As `memcpy`: `src` readable and `dst` writable for `n` bytes; if
/// they overlap, `dst` is not above `src`.
#[inline(always)]
unsafe fn forward(dst: *mut u8, src: *const u8, n: usize) {
    for i in 0..n {
        // SAFETY: the caller's contract.
        unsafe { dst.add(i).write_volatile(src.add(i).read()) };
    }
}

/// Copies `n` bytes, a word per step while at least 4 remain.
///
/// # Safety
/// As `forward`, and `dst` and `src` 4-byte aligned.
#[inline(always)]
unsafe fn forward_words(dst: *mut u8, src: *const u8, n: usize) {
    let words = n / 4;
    for i in 0..words {
        // SAFETY: the caller's contract; both are 4-byte aligned.
        unsafe {
            (dst as *mut u32)
                .add(i)
                .write_volatile((src as *const u32).add(i).read())
        };
    }
    let done = words * 4;
    // SAFETY: the caller's contract, for the rest.
    unsafe { forward(dst.add(done), src.add(done), n - done) };
}

/// Fills `n` bytes with `c`.
///
/// # Safety
/// As `memset`: `dst` writable for `n` bytes.
#[inline(always)]
unsafe fn fill(dst: *mut u8, c: u8, n: usize) {
    for i in 0..n {
        // SAFETY: the caller's contract.
        unsafe { dst.add(i).write_volatile(c) };
    }
}

/// Copies `n` bytes; `dst` and `src` may overlap.
///
/// # Safety
/// As `memmove`: `src` readable and `dst` writable for `n` bytes.
#[inline(always)]
unsafe fn move_bytes(dst: *mut u8, src: *const u8, n: usize) {
    if (dst as usize) <= (src as usize) {
        // SAFETY: the caller's contract; `dst` is not above `src`.
        unsafe { forward(dst, src, n) };
    } else {
        for i in (0..n).rev() {
            // SAFETY: the caller's contract; backwards, as `dst` is
            // above `src`.
            unsafe { dst.add(i).write_volatile(src.add(i).read()) };
        }
    }
}

/// Compares `n` bytes: 0 if equal, else the difference of the first
/// bytes that differ.
///
/// # Safety
/// As `memcmp`: `a` and `b` readable for `n` bytes.
#[inline(always)]
unsafe fn compare(a: *const u8, b: *const u8, n: usize) -> i32 {
    for i in 0..n {
        // SAFETY: the caller's contract.
        let (x, y) = unsafe { (a.add(i).read_volatile(), b.add(i).read_volatile()) };
        if x != y {
            return i32::from(x) - i32::from(y);
        }
    }
    0
}

/// `memcpy`.
///
/// # Safety
/// `src` readable and `dst` writable for `n` bytes, not overlapping.
#[no_mangle]
pub unsafe extern "C" fn memcpy(dst: *mut u8, src: *const u8, n: usize) -> *mut u8 {
    // SAFETY: the caller's contract.
    unsafe { forward(dst, src, n) };
    dst
}

/// `memmove`.
///
/// # Safety
/// `src` readable and `dst` writable for `n` bytes; they may overlap.
#[no_mangle]
pub unsafe extern "C" fn memmove(dst: *mut u8, src: *const u8, n: usize) -> *mut u8 {
    // SAFETY: the caller's contract.
    unsafe { move_bytes(dst, src, n) };
    dst
}

/// `memset`.
///
/// # Safety
/// `dst` writable for `n` bytes.
#[no_mangle]
pub unsafe extern "C" fn memset(dst: *mut u8, c: i32, n: usize) -> *mut u8 {
    // SAFETY: the caller's contract.
    unsafe { fill(dst, c as u8, n) };
    dst
}

/// `memcmp` (also `bcmp`, which only needs zero or not).
///
/// # Safety
/// `a` and `b` readable for `n` bytes.
#[no_mangle]
pub unsafe extern "C" fn memcmp(a: *const u8, b: *const u8, n: usize) -> i32 {
    // SAFETY: the caller's contract.
    unsafe { compare(a, b, n) }
}

/// `bcmp`.
///
/// # Safety
/// As [`memcmp`].
#[no_mangle]
pub unsafe extern "C" fn bcmp(a: *const u8, b: *const u8, n: usize) -> i32 {
    // SAFETY: the caller's contract.
    unsafe { compare(a, b, n) }
}

/// `__aeabi_memcpy`.
///
/// # Safety
/// As [`memcpy`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memcpy(dst: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { forward(dst, src, n) };
}

/// `__aeabi_memcpy4`.
///
/// # Safety
/// As [`memcpy`], and both 4-byte aligned.
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memcpy4(dst: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { forward_words(dst, src, n) };
}

/// `__aeabi_memcpy8`.
///
/// # Safety
/// As [`memcpy`], and both 8-byte aligned.
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memcpy8(dst: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { forward_words(dst, src, n) };
}

/// `__aeabi_memmove` (and its aligned forms below).
///
/// # Safety
/// As [`memmove`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memmove(dst: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { move_bytes(dst, src, n) };
}

/// `__aeabi_memmove4`.
///
/// # Safety
/// As [`memmove`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memmove4(dst: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { move_bytes(dst, src, n) };
}

/// `__aeabi_memmove8`.
///
/// # Safety
/// As [`memmove`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memmove8(dst: *mut u8, src: *const u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { move_bytes(dst, src, n) };
}

/// `__aeabi_memset` (note the argument order: length, then value).
///
/// # Safety
/// As [`memset`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memset(dst: *mut u8, n: usize, c: i32) {
    // SAFETY: the caller's contract.
    unsafe { fill(dst, c as u8, n) };
}

/// `__aeabi_memset4`.
///
/// # Safety
/// As [`memset`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memset4(dst: *mut u8, n: usize, c: i32) {
    // SAFETY: the caller's contract.
    unsafe { fill(dst, c as u8, n) };
}

/// `__aeabi_memset8`.
///
/// # Safety
/// As [`memset`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memset8(dst: *mut u8, n: usize, c: i32) {
    // SAFETY: the caller's contract.
    unsafe { fill(dst, c as u8, n) };
}

/// `__aeabi_memclr`.
///
/// # Safety
/// As [`memset`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memclr(dst: *mut u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { fill(dst, 0, n) };
}

/// `__aeabi_memclr4`.
///
/// # Safety
/// As [`memset`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memclr4(dst: *mut u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { fill(dst, 0, n) };
}

/// `__aeabi_memclr8`.
///
/// # Safety
/// As [`memset`].
#[no_mangle]
pub unsafe extern "aapcs" fn __aeabi_memclr8(dst: *mut u8, n: usize) {
    // SAFETY: the caller's contract.
    unsafe { fill(dst, 0, n) };
}
