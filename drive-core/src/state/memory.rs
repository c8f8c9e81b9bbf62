//! The multi-segment programs' memory (seed 002's registers 1024-1536), which the drive is
//! handed beside the PVT point table: what a master wrote, what a save writes and power-up
//! loads. [`super::program`] runs what it holds.

use core::sync::atomic::{AtomicU16, Ordering};

/// Registers of the program (1024..=1536).
pub const WORDS: usize = 513;

/// The program's registers (1 KB), as a master wrote them or power-up loaded them.
///
/// Its words are atomic so that a microcontroller keeps it in a static that power-up loads and
/// the drive writes through shared references; only the bus side reads or writes it.
#[derive(Debug)]
pub struct ProgramMemory {
    words: [AtomicU16; WORDS],
}

impl ProgramMemory {
    /// Every word 0 (an empty program). A `const fn`, so that it is built where it is stored.
    pub const fn new() -> Self {
        Self { words: [const { AtomicU16::new(0) }; WORDS] }
    }

    /// Register `k` (1024 + k), if there is such a register.
    pub fn word(&self, k: usize) -> Option<u16> {
        self.words.get(k).map(|w| w.load(Ordering::Relaxed))
    }

    /// Sets register `k` to `v` (nothing past the end).
    pub fn set_word(&self, k: usize, v: u16) {
        if let Some(w) = self.words.get(k) {
            w.store(v, Ordering::Relaxed);
        }
    }

    /// Every word 0.
    pub fn clear(&self) {
        for w in &self.words {
            w.store(0, Ordering::Relaxed);
        }
    }
}

impl Default for ProgramMemory {
    fn default() -> Self {
        Self::new()
    }
}

impl Clone for ProgramMemory {
    fn clone(&self) -> Self {
        let copy = Self::new();
        for k in 0..WORDS {
            copy.set_word(k, self.word(k).unwrap_or(0));
        }
        copy
    }
}
