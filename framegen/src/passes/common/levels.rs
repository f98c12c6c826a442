//! Pyramids of grids, each level ¼ the pixels of the one above (half the
//! width and height, rounded up), stored back to back in one buffer. Used by
//! the background layers (GFFE §4.2) and push-pull.

/// The layout of a pyramid over a `width × height` base.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Levels {
    /// Number of levels (0 = none).
    pub count: u32,
    /// Width of level 0.
    pub width: u32,
    /// Height of level 0.
    pub height: u32,
}

impl Levels {
    /// A pyramid of `count` levels over a `width × height` base.
    pub fn new(count: u32, width: u32, height: u32) -> Self {
        Self {
            count,
            width,
            height,
        }
    }

    /// The most levels a `width × height` base has before it reaches 1×1.
    pub fn full_depth(width: u32, height: u32) -> u32 {
        32 - width.max(height).max(1).leading_zeros()
    }

    /// Width and height of level `l`.
    pub fn size(&self, l: u32) -> (u32, u32) {
        let s = 1u64 << l.min(31);
        (
            (u64::from(self.width).div_ceil(s)) as u32,
            (u64::from(self.height).div_ceil(s)) as u32,
        )
    }

    /// Pixels of level `l`.
    pub fn len(&self, l: u32) -> u32 {
        let (w, h) = self.size(l);
        w * h
    }

    /// Whether the pyramid has no pixels.
    pub fn is_empty(&self) -> bool {
        self.total() == 0
    }

    /// Index of level `l`'s first pixel.
    pub fn offset(&self, l: u32) -> u32 {
        (0..l).map(|i| self.len(i)).sum()
    }

    /// Pixels of all levels.
    pub fn total(&self) -> u32 {
        self.offset(self.count)
    }

    /// The level holding global index `i`.
    pub fn level_of(&self, i: u32) -> u32 {
        let mut end = 0;
        for l in 0..self.count {
            end += self.len(l);
            if i < end {
                return l;
            }
        }
        self.count
    }

    /// The size of pixels of level `l` in level-0 pixels.
    pub fn scale(l: u32) -> f32 {
        (1u64 << l.min(31)) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_round_up_and_offsets_add_up() {
        let p = Levels::new(3, 5, 3);
        assert_eq!(p.size(0), (5, 3));
        assert_eq!(p.size(1), (3, 2));
        assert_eq!(p.size(2), (2, 1));
        assert_eq!(p.offset(1), 15);
        assert_eq!(p.offset(2), 21);
        assert_eq!(p.total(), 23);
        assert_eq!(p.level_of(14), 0);
        assert_eq!(p.level_of(15), 1);
        assert_eq!(p.level_of(22), 2);
        assert_eq!(Levels::full_depth(1, 1), 1);
        assert_eq!(Levels::full_depth(1280, 720), 11);
    }
}
