//! Helpers shared by the simulator's tests: requests to a plant's drive in frames.
#![allow(dead_code)]

use hal_sim::plant::Plant;

/// Sends a request (CRC appended) at the plant's time and runs until it is answered.
pub fn send(plant: &mut Plant, body: &[u8]) -> Vec<u8> {
    plant.request(body).unwrap_or_else(|| panic!("no reply to {body:02X?}"))
}

/// Writes `value` to register `reg` (function 0x06, node 1); the write must be echoed.
pub fn write(plant: &mut Plant, reg: u16, value: u16) {
    let [rh, rl] = reg.to_be_bytes();
    let [vh, vl] = value.to_be_bytes();
    let r = send(plant, &[0x01, 0x06, rh, rl, vh, vl]);
    assert_eq!(r[1], 0x06, "{reg:04X}: {r:02X?}");
}
