//! A small palette of an exemplar's colours (k-means), so that a colour
//! histogram counts joint colours rather than three channels apart: a
//! vein's dark red and a background's pale pink stay distinct entries even
//! where their channels' marginals overlap (Chen & Wang's index histogram).

use crate::hash::{hash_pos, unit};

/// Palette entries: enough to separate rare feature colours from the bulk.
const ENTRIES: usize = 32;
/// Lloyd iterations after the seeding.
const ROUNDS: usize = 12;
const TAG: u32 = 0x5041_4c01;

/// Colour centres, fitted to a set of colours.
pub struct Palette {
    centres: Vec<[f32; 3]>,
}

impl Palette {
    /// k-means++ seeding by hashed draws, then Lloyd iterations.
    pub fn fit(colours: &[[f32; 3]], seed: u64) -> Palette {
        let mut centres: Vec<[f32; 3]> = vec![colours[0]];
        let mut nearest = vec![f32::INFINITY; colours.len()];
        while centres.len() < ENTRIES.min(colours.len()) {
            let last = *centres.last().expect("seeded");
            let mut total = 0f64;
            for (d, c) in nearest.iter_mut().zip(colours) {
                *d = d.min(dist(*c, last));
                total += *d as f64;
            }
            if total == 0.0 {
                break;
            }
            let pick = unit(hash_pos(seed, 0, TAG, [centres.len() as i64, 0, 0])) as f64 * total;
            let mut acc = 0f64;
            let mut chosen = colours.len() - 1;
            for (i, d) in nearest.iter().enumerate() {
                acc += *d as f64;
                if acc >= pick {
                    chosen = i;
                    break;
                }
            }
            centres.push(colours[chosen]);
        }
        let mut palette = Palette { centres };
        for _ in 0..ROUNDS {
            let mut sums = vec![[0f64; 4]; palette.centres.len()];
            for c in colours {
                let s = &mut sums[palette.nearest(*c) as usize];
                for ch in 0..3 {
                    s[ch] += c[ch] as f64;
                }
                s[3] += 1.0;
            }
            for (centre, s) in palette.centres.iter_mut().zip(&sums) {
                if s[3] > 0.0 {
                    *centre = [0, 1, 2].map(|ch| (s[ch] / s[3]) as f32);
                }
            }
        }
        palette
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.centres.len()
    }

    /// The entry nearest `c`.
    pub fn nearest(&self, c: [f32; 3]) -> u16 {
        let mut best = 0;
        let mut best_d = f32::INFINITY;
        for (i, &p) in self.centres.iter().enumerate() {
            let d = dist(c, p);
            if d < best_d {
                best_d = d;
                best = i;
            }
        }
        best as u16
    }
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distinct_colours_get_distinct_entries() {
        let mut colours = vec![[230.0, 200.0, 200.0]; 1000];
        colours.extend(vec![[90.0, 20.0, 30.0]; 10]);
        let p = Palette::fit(&colours, 7);
        assert_ne!(
            p.nearest([230.0, 200.0, 200.0]),
            p.nearest([90.0, 20.0, 30.0])
        );
    }
}
