//! The stack's high-water mark: the free stack is painted at power-up, and the deepest word
//! no longer holding the paint is as far as the stack has reached since.
//!
//! With flip-link the stack is the RAM below the statics, from `_stack_start` (the initial
//! stack pointer) down to `_stack_end` (the start of RAM); the budget's RAM figure is the
//! statics plus what this measures, not an allowance. `cargo xtask tick-cost` reads the
//! painted region of the QEMU build through QEMU's monitor; the G474 logs [`peak`].

/// The paint: "STK!" as a little-endian word, unlikely as a saved register or a local.
pub const PAINT: u32 = 0x214B_5453;

/// Bytes left unpainted below the stack pointer of [`paint`]'s caller: its own frame and the
/// interrupts that may preempt it.
const MARGIN: usize = 256;

unsafe extern "C" {
    /// The lowest address of the stack (cortex-m-rt's linker script, moved by flip-link).
    static _stack_end: u32;
    /// The highest: the initial stack pointer.
    static _stack_start: u32;
}

/// The stack region, `(lowest address, initial stack pointer)`.
fn region() -> (usize, usize) {
    // Only the addresses are taken: nothing is read through these symbols.
    (&raw const _stack_end as usize, &raw const _stack_start as usize)
}

/// Paints the free stack below the caller. Call it first at power-up, before anything deep.
#[inline(never)]
pub fn paint() {
    let (bottom, _) = region();
    let sp = cortex_m::register::msp::read() as usize;
    let mut p = bottom;
    while p + MARGIN < sp {
        // SAFETY: below the stack pointer and above the stack's end: memory no frame uses yet.
        unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

/// Bytes of stack used at the most since [`paint`]: from the initial stack pointer down to the
/// deepest word whose paint is gone.
#[cfg_attr(feature = "qemu", allow(dead_code, reason = "the QEMU build is read by its monitor"))]
pub fn peak() -> usize {
    let (bottom, top) = region();
    let mut p = bottom;
    // SAFETY: reads of the stack region, within the RAM the linker gave it.
    while p < top && unsafe { core::ptr::read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    top - p
}
