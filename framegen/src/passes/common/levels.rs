//! Pyramids of grids, each level ¼ the pixels of the one above (half the
//! width and height, rounded up), stored back to back in one buffer. Used by
//! the background layers (GFFE §4.2) and push-pull.

use glam::Vec2;

use crate::passes::common::camera::cell;

/// Level `l` of a pyramid as a loop over many fragments needs it: where the
/// level starts in the buffer, its grid and its cell size, computed once
/// per level (see [`Levels::grid`]) instead of from the pyramid per
/// fragment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Index of the level's first cell in the pyramid's buffer.
    pub offset: u32,
    /// Width of the level in cells.
    pub width: u32,
    /// Height of the level in cells.
    pub height: u32,
    /// A cell's size in level-0 pixels.
    pub scale: f32,
}

impl Grid {
    /// Buffer index of the cell containing level-0 position `px`; `None`
    /// outside the level (WGSL: `offset + cell(px, w, h, scale)`).
    #[inline]
    pub fn slot(&self, px: Vec2) -> Option<u32> {
        cell(px, self.width, self.height, self.scale).map(|s| self.offset + s)
    }
}

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

    /// Level `l`'s place and grid.
    pub fn grid(&self, l: u32) -> Grid {
        let (width, height) = self.size(l);
        Grid {
            offset: self.offset(l),
            width,
            height,
            scale: Self::scale(l),
        }
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

    #[test]
    fn a_grid_finds_the_cell_of_its_level() {
        let p = Levels::new(3, 5, 3);
        let g = p.grid(1);
        assert_eq!((g.offset, g.width, g.height, g.scale), (15, 3, 2, 2.0));
        // Level-0 pixel (4.5, 2.5) lies in level 1's cell (2, 1).
        assert_eq!(g.slot(Vec2::new(4.5, 2.5)), Some(15 + 3 + 2));
        assert_eq!(g.slot(Vec2::new(0.0, 0.0)), Some(15));
        // Past the level's cells (3 × 2 cells of 2 pixels), or not a number.
        assert_eq!(g.slot(Vec2::new(6.0, 0.0)), None);
        assert_eq!(g.slot(Vec2::new(0.0, 4.0)), None);
        assert_eq!(g.slot(Vec2::new(-0.1, 0.0)), None);
        assert_eq!(g.slot(Vec2::new(f32::NAN, 0.0)), None);
        for l in 0..3 {
            let g = p.grid(l);
            let (w, h) = p.size(l);
            assert_eq!((g.offset, g.width, g.height), (p.offset(l), w, h));
            assert_eq!(g.scale, Levels::scale(l));
        }
    }
}
