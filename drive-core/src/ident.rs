//! Who the drive says it is: the strings of 0x101A..0x1025 and of function 0x2B / 0x0E.

/// The identification strings. Each platform (board, simulator) supplies its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Identity {
    /// Device identification object 0x00.
    pub vendor_name: &'static str,
    /// Object 0x01.
    pub product_code: &'static str,
    /// Object 0x02, `major.minor` (and patch).
    pub revision: &'static str,
    /// Object 0x03.
    pub vendor_url: &'static str,
    /// Object 0x04.
    pub product_name: &'static str,
    /// Object 0x05.
    pub model_name: &'static str,
    /// Object 0x06.
    pub user_application_name: &'static str,
    /// Register 0x101A..0x1021 (16 bytes, zero padded).
    pub device_name: &'static str,
    /// Register 0x1022..0x1023 (4 bytes).
    pub hardware_version: &'static str,
    /// Register 0x1024..0x1025 (4 bytes).
    pub software_version: &'static str,
}

impl Identity {
    /// The drive in the simulator.
    pub const SIMULATOR: Identity = Identity {
        vendor_name: "OpenStep Motion",
        product_code: "OSD-MSME",
        revision: env!("CARGO_PKG_VERSION"),
        vendor_url: "https://example.invalid/openstep",
        product_name: "OpenStep integrated stepper drive",
        model_name: "OSD-42 simulated",
        user_application_name: "drive-core",
        device_name: "OSD-42",
        hardware_version: "SIM1",
        software_version: "V010",
    };

    /// Device identification object `id` (0x00..=0x06), if the drive has it.
    pub fn object(&self, id: u8) -> Option<&'static str> {
        Some(match id {
            0 => self.vendor_name,
            1 => self.product_code,
            2 => self.revision,
            3 => self.vendor_url,
            4 => self.product_name,
            5 => self.model_name,
            6 => self.user_application_name,
            _ => return None,
        })
    }
}

/// The number a version part's digits make (a cargo version part is digits only).
#[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
const fn number(s: &str) -> u32 {
    let b = s.as_bytes();
    let (mut n, mut i) = (0u32, 0);
    while i < b.len() {
        if let Some(d) = (b[i] as char).to_digit(10) {
            n = n * 10 + d;
        }
        i += 1;
    }
    n
}

/// The crate's version as a firmware image's header has it: major << 16 | minor << 8 | patch.
pub const VERSION: u32 = number(env!("CARGO_PKG_VERSION_MAJOR")) << 16
    | number(env!("CARGO_PKG_VERSION_MINOR")) << 8
    | number(env!("CARGO_PKG_VERSION_PATCH"));

/// The crate's version as major × 100 + minor (`0.1.x` is 1).
pub const SOFTWARE_REVISION: u16 =
    (number(env!("CARGO_PKG_VERSION_MAJOR")) * 100 + number(env!("CARGO_PKG_VERSION_MINOR"))) as u16;
