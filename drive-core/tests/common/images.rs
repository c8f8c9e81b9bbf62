//! Signed images for the update tests, with the repository's test key.
#![allow(dead_code)]

use drive_core::update::{Board, Header, digest};
use ed25519_dalek::{Signer, SigningKey};

/// The 32 bytes in hex in the repository's key file `name` (`keys/`).
pub fn key_file(name: &str) -> [u8; 32] {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../keys/").to_owned() + name;
    let text = std::fs::read_to_string(&path).expect("key file");
    drive_core::update::key_from_hex(&text).expect("32 bytes in hex")
}

/// The repository's test key.
pub fn test_key() -> SigningKey {
    SigningKey::from_bytes(&key_file("test.key"))
}

/// An image of `program` for `board`, version 2.1.0, reading stores from version `store`,
/// signed with `key`.
pub fn image(key: &SigningKey, board: Board, program: &[u8], store: u16) -> Vec<u8> {
    let header = Header { board, version: 0x0002_0100, length: program.len() as u32, store };
    let mut bytes = header.to_bytes().to_vec();
    bytes.extend_from_slice(program);
    let signature = key.sign(&digest(&bytes));
    bytes.extend_from_slice(&signature.to_bytes());
    bytes
}
