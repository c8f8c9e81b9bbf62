//! Signed firmware images: an image signed with the test key is taken, and an unsigned,
//! foreign-key, wrong-board, truncated, lengthened or corrupted one is refused with its reason.

mod common;

use common::images::{image, key_file, test_key};
use drive_core::update::{Board, HEADER_LEN, Header, KEY_LEN, Refusal, SIGNATURE_LEN, TEST_KEY, Verifier};
use ed25519_dalek::SigningKey;
use proptest::prelude::*;

/// The verdict on `image` as a drive on `board` with store version 1 and key `key` gives it,
/// its bytes taken in pieces of `piece`.
fn verdict(image: &[u8], piece: usize, key: &[u8; KEY_LEN], board: Board) -> Result<Header, Refusal> {
    let (body, signature) = image.split_at(image.len().saturating_sub(SIGNATURE_LEN));
    let mut v = Verifier::new();
    for chunk in body.chunks(piece.max(1)) {
        v.absorb(chunk);
    }
    let signature: [u8; SIGNATURE_LEN] = signature.try_into().unwrap_or([0; SIGNATURE_LEN]);
    v.finish(&signature, key, board, 1)
}

const PROGRAM: &[u8] = &[0x5A; 3000];

#[test]
fn the_test_key_pair_is_the_one_the_drive_knows() {
    assert_eq!(test_key().verifying_key().to_bytes(), TEST_KEY);
    assert_eq!(key_file("test.pub"), TEST_KEY);
}

#[test]
fn a_signed_image_is_taken_in_any_pieces() {
    let img = image(&test_key(), Board::Simulator, PROGRAM, 1);
    for piece in [1, 7, 32, 128, img.len()] {
        let h = verdict(&img, piece, &TEST_KEY, Board::Simulator).expect("taken");
        assert_eq!((h.version, h.length), (0x0002_0100, 3000));
    }
}

#[test]
fn every_bad_image_is_refused_with_its_reason() {
    let key = test_key();
    let good = image(&key, Board::Simulator, PROGRAM, 1);
    let check = |img: &[u8], why| assert_eq!(verdict(img, 64, &TEST_KEY, Board::Simulator), Err(why));
    // Unsigned: no signature at all (the program's last bytes taken for one), or zeros.
    check(&good[..good.len() - SIGNATURE_LEN], Refusal::Length);
    let mut unsigned = good.clone();
    unsigned[good.len() - SIGNATURE_LEN..].fill(0);
    check(&unsigned, Refusal::Signature);
    // Another key.
    let foreign = SigningKey::from_bytes(&[7; 32]);
    check(&image(&foreign, Board::Simulator, PROGRAM, 1), Refusal::Signature);
    // Another board.
    check(&image(&key, Board::G474, PROGRAM, 1), Refusal::Board);
    // Truncated, or with bytes added.
    check(&good[..good.len() - 100], Refusal::Length);
    let mut longer = good.clone();
    longer.splice(HEADER_LEN..HEADER_LEN, [0u8; 4]);
    check(&longer, Refusal::Length);
    // Not an image.
    let mut magic = good.clone();
    magic[0] = b'X';
    check(&magic, Refusal::NotAnImage);
    // A newer store than this drive's.
    check(&image(&key, Board::Simulator, PROGRAM, 2), Refusal::Store);
}

proptest! {
    // A signature's check is some milliseconds in a debug build.
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// One byte changed anywhere (header, program or signature) and the image is refused.
    #[test]
    fn any_changed_byte_is_refused(at in 0usize..HEADER_LEN + 3000 + SIGNATURE_LEN, flip in 1u8..=255) {
        let mut img = image(&test_key(), Board::Simulator, PROGRAM, 1);
        img[at] ^= flip;
        prop_assert!(verdict(&img, 256, &TEST_KEY, Board::Simulator).is_err());
    }
}
