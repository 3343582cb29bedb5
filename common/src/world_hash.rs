//! One number per world sample that says whether two worlds are the same world, bit for bit
//! (`handblocks inspect FILE --world-hashes`): two participants of a shared session each record
//! it, and their recordings are compared line by line, step by step.
//!
//! The hash is FNV-1a 64 (offset basis `0xcbf29ce484222325`, prime `0x100000001b3`) over the
//! little-endian bytes of, in this order:
//!
//! 1. `step` (u64), `block_count` (u32), `grasped_block` (i32);
//! 2. for each block `block_count` counts (never more than the slice holds): its pose's
//!    `position[0..3]` then `rotation[0..4]`, each as its f64 bit pattern (`to_bits`, u64),
//!    then `mode` (u32) and `held_by` (u32).
//!
//! Nothing else: not the stamp (its clock times differ between machines), not `hand_seq` (each
//! participant numbers its hand samples its own way), not the drawn finger points (how the hand
//! is shown, not what the world is). The values are compared as bits, so `-0.0` and `0.0`
//! differ, as a NaN's payloads do: the same world is the same bits.
//!
//! Why this and not `std::hash`: two machines' recordings are compared line by line, so the
//! value must depend on the world alone, never on the Rust version, the platform or the
//! process. std's `DefaultHasher` promises none of that (its algorithm may change between
//! releases, and a `RandomState` is seeded per process), and `Hash` impls may feed bytes in
//! platform order. FNV-1a is a few lines, fixed for ever, needs no dependency and allocates
//! nothing; it is no defence against someone forging a collision, which nobody here does.

use crate::samples::{BlockState, WorldHeader, WorldView};

/// FNV-1a 64's offset basis.
const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
/// FNV-1a 64's prime.
const PRIME: u64 = 0x0000_0100_0000_01b3;

/// FNV-1a 64, fed a field's little-endian bytes at a time.
struct Fnv1a(u64);

impl Fnv1a {
    fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(PRIME);
        }
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
}

/// The world's hash (the module's definition): the same for the same step, block count,
/// grasped block and counted blocks' poses (bit for bit), modes and hands, whatever the stamp,
/// the hand seq, the finger points or the blocks past `block_count`.
pub fn world_hash(header: &WorldHeader, blocks: &[BlockState]) -> u64 {
    let mut h = Fnv1a(OFFSET_BASIS);
    h.u64(header.step);
    h.u32(header.block_count);
    h.bytes(&header.grasped_block.to_le_bytes());
    let counted = (header.block_count as usize).min(blocks.len());
    for b in &blocks[..counted] {
        for &v in b.pose.position.iter().chain(&b.pose.rotation) {
            h.f64(v);
        }
        h.u32(b.mode);
        h.u32(b.held_by);
    }
    h.0
}

/// [`world_hash`] of a world read in place (a received sample, a [`crate::WorldSample`]'s
/// view).
pub fn of_view(w: &WorldView<'_>) -> u64 {
    world_hash(w.header, w.blocks)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::samples::{BlockMode, Pose, WorldSample};
    use crate::Stamp;

    /// Three blocks in different places, the second grasped by the right hand.
    fn world() -> WorldSample {
        let mut w = WorldSample::with_blocks(3);
        w.header.step = 1234;
        w.header.grasped_block = 1;
        for (i, b) in w.blocks.iter_mut().enumerate() {
            b.pose = Pose {
                position: [0.1 * i as f64, 0.05, -0.2],
                rotation: [0.0, 0.0, 0.0, 1.0],
            };
            b.mode = BlockMode::Resting as u32;
        }
        w.blocks[1].mode = BlockMode::Grasped as u32;
        w.blocks[1].held_by = 1;
        w
    }

    fn hash(w: &WorldSample) -> u64 {
        of_view(&w.view())
    }

    #[test]
    fn fnv1a_is_the_published_one() {
        // The FNV reference vectors: "" and "a".
        let mut h = Fnv1a(OFFSET_BASIS);
        assert_eq!(h.0, 0xcbf29ce484222325);
        h.bytes(b"a");
        assert_eq!(h.0, 0xaf63dc4c8601ec8c);
    }

    #[test]
    fn equal_worlds_hash_equal_and_the_value_is_fixed() {
        assert_eq!(hash(&world()), hash(&world()));
        assert_eq!(world_hash(&world().header, &world().blocks), hash(&world()));
        // The definition, spelled out byte by byte: a change to the function that changes
        // the value breaks every comparison with an older recording's hashes.
        let w = world();
        let mut bytes = Vec::new();
        bytes.extend(w.step.to_le_bytes());
        bytes.extend(w.block_count.to_le_bytes());
        bytes.extend(w.grasped_block.to_le_bytes());
        for b in &w.blocks {
            for v in b.pose.position.iter().chain(&b.pose.rotation) {
                bytes.extend(v.to_bits().to_le_bytes());
            }
            bytes.extend(b.mode.to_le_bytes());
            bytes.extend(b.held_by.to_le_bytes());
        }
        let mut h = Fnv1a(OFFSET_BASIS);
        h.bytes(&bytes);
        assert_eq!(hash(&w), h.0);
        // And the empty world's, pinned.
        let empty = WorldHeader::default();
        let mut h = Fnv1a(OFFSET_BASIS);
        h.bytes(&[0; 8]);
        h.bytes(&[0; 4]);
        h.bytes(&(-1i32).to_le_bytes());
        assert_eq!(world_hash(&empty, &[]), h.0);
    }

    #[test]
    fn what_makes_the_world_changes_the_hash() {
        let base = hash(&world());
        let changed = |f: &dyn Fn(&mut WorldSample)| {
            let mut w = world();
            f(&mut w);
            hash(&w)
        };
        // One ulp of one coordinate, of a rotation, and a zero's sign.
        assert_ne!(
            changed(&|w| w.blocks[2].pose.position[1] = f64::from_bits(0.05f64.to_bits() + 1)),
            base
        );
        assert_ne!(
            changed(&|w| w.blocks[0].pose.rotation[3] = f64::from_bits(1f64.to_bits() - 1)),
            base
        );
        assert_ne!(changed(&|w| w.blocks[0].pose.position[0] = -0.0), base);
        assert_ne!(
            changed(&|w| w.blocks[0].mode = BlockMode::Tipping as u32),
            base
        );
        assert_ne!(changed(&|w| w.blocks[1].held_by = 3), base);
        assert_ne!(changed(&|w| w.header.step += 1), base);
        assert_ne!(changed(&|w| w.header.grasped_block = -1), base);
        assert_ne!(changed(&|w| w.header.block_count = 2), base);
        // Two blocks swapped are another world.
        assert_ne!(changed(&|w| w.blocks.swap(0, 2)), base);
    }

    #[test]
    fn stamps_hand_seqs_and_finger_points_do_not() {
        let base = hash(&world());
        let mut w = world();
        w.header.stamp = Stamp {
            seq: 77,
            source_time_ns: 1,
            origin_ns: 2,
            publish_ns: 3,
        };
        w.header.hand_seq = 99;
        w.header.finger_count = 1;
        w.header.finger_point_count[0] = 2;
        w.header.finger_points[0][1] = [0.3, 0.2, 0.1];
        assert_eq!(hash(&w), base);
    }

    #[test]
    fn blocks_past_the_count_are_ignored() {
        let mut w = world();
        w.header.block_count = 2;
        let two = hash(&w);
        w.blocks[2].pose.position[0] = 5.0;
        w.blocks.push(BlockState::default());
        assert_eq!(hash(&w), two);
        // The same two blocks alone, counted the same.
        w.blocks.truncate(2);
        assert_eq!(hash(&w), two);
        // A count past the slice hashes the blocks there are (and the count it says).
        w.header.block_count = 10;
        let mut fewer = world();
        fewer.header.block_count = 10;
        fewer.blocks.truncate(2);
        assert_eq!(hash(&w), hash(&fewer));
        assert_ne!(hash(&w), two);
    }
}
