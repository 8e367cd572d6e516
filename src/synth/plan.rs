//! Dependency planning: which voxels of which level and step a request
//! needs, for both correction schemes.

/// Splits cells into groups whose bounding boxes are not much larger than
/// the cells themselves (so a standard-scheme batch never synthesizes the
/// empty space between scattered cells).
pub fn group_cells(cells: &[[i64; 3]], _cell: i64) -> Vec<Vec<[i64; 3]>> {
    let mut out = Vec::new();
    split(cells.to_vec(), &mut out);
    out
}

fn split(mut cells: Vec<[i64; 3]>, out: &mut Vec<Vec<[i64; 3]>>) {
    if cells.is_empty() {
        return;
    }
    let lo = [0, 1, 2].map(|a| cells.iter().map(|c| c[a]).min().expect("non-empty"));
    let hi = [0, 1, 2].map(|a| cells.iter().map(|c| c[a]).max().expect("non-empty"));
    let ext = [0, 1, 2].map(|a| hi[a] - lo[a] + 1);
    let volume: i64 = ext.iter().product();
    if cells.len() == 1 || volume <= 2 * cells.len() as i64 {
        out.push(cells);
        return;
    }
    let axis = (0..3)
        .max_by_key(|&a| (ext[a], -(a as i64)))
        .expect("three axes");
    cells.sort_by_key(|c| (c[axis], c[(axis + 1) % 3], c[(axis + 2) % 3]));
    let right = cells.split_off(cells.len() / 2);
    split(cells, out);
    split(right, out);
}
