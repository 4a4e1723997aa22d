//! ALS point columns as the kernels consume them (structure of arrays).

/// A set of ALS returns, one entry per point in every column (structure of arrays).
///
/// Coordinates are in the tile's projected CRS (metres) with heights as stored in the file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AlsPoints {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
    /// Raw LAS intensity.
    pub intensity: Vec<u16>,
    pub return_number: Vec<u8>,
    pub number_of_returns: Vec<u8>,
    /// ASPRS class (2 = ground).
    pub classification: Vec<u8>,
    /// Scan angle in degrees (formats 6–10 converted from 0.006° units).
    pub scan_angle_deg: Vec<f32>,
    /// GPS time as stored (NaN when the point format has none).
    pub gps_time: Vec<f64>,
    pub point_source_id: Vec<u16>,
}

impl AlsPoints {
    /// Intensity of point `i`, 0 read as 1 (the `int` and `share` weightings).
    pub fn intensity_or_one(&self, i: usize) -> u16 {
        self.intensity[i].max(1)
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when there is no point.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Empty set with room for `n` points in every column.
    pub fn with_capacity(n: usize) -> Self {
        AlsPoints {
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            intensity: Vec::with_capacity(n),
            return_number: Vec::with_capacity(n),
            number_of_returns: Vec::with_capacity(n),
            classification: Vec::with_capacity(n),
            scan_angle_deg: Vec::with_capacity(n),
            gps_time: Vec::with_capacity(n),
            point_source_id: Vec::with_capacity(n),
        }
    }

    /// Append every point of `other`.
    pub fn extend_from(&mut self, other: &AlsPoints) {
        self.x.extend_from_slice(&other.x);
        self.y.extend_from_slice(&other.y);
        self.z.extend_from_slice(&other.z);
        self.intensity.extend_from_slice(&other.intensity);
        self.return_number.extend_from_slice(&other.return_number);
        self.number_of_returns.extend_from_slice(&other.number_of_returns);
        self.classification.extend_from_slice(&other.classification);
        self.scan_angle_deg.extend_from_slice(&other.scan_angle_deg);
        self.gps_time.extend_from_slice(&other.gps_time);
        self.point_source_id.extend_from_slice(&other.point_source_id);
    }
}

impl AlsPoints {
    /// The points in the order given by `order` (indices into `self`), every column permuted.
    pub fn permuted(&self, order: &[u32]) -> AlsPoints {
        fn pick<T: Copy>(v: &[T], order: &[u32]) -> Vec<T> {
            order.iter().map(|&i| v[i as usize]).collect()
        }
        AlsPoints {
            x: pick(&self.x, order),
            y: pick(&self.y, order),
            z: pick(&self.z, order),
            intensity: pick(&self.intensity, order),
            return_number: pick(&self.return_number, order),
            number_of_returns: pick(&self.number_of_returns, order),
            classification: pick(&self.classification, order),
            scan_angle_deg: pick(&self.scan_angle_deg, order),
            gps_time: pick(&self.gps_time, order),
            point_source_id: pick(&self.point_source_id, order),
        }
    }

    /// [`AlsPoints::permuted`] in place of `self`, a column at a time: memory grows by one
    /// column's worth, not by a second copy of the points.
    pub fn permute(&mut self, order: &[u32]) {
        fn pick<T: Copy>(v: &mut Vec<T>, order: &[u32]) {
            *v = order.iter().map(|&i| v[i as usize]).collect();
        }
        pick(&mut self.x, order);
        pick(&mut self.y, order);
        pick(&mut self.z, order);
        pick(&mut self.intensity, order);
        pick(&mut self.return_number, order);
        pick(&mut self.number_of_returns, order);
        pick(&mut self.classification, order);
        pick(&mut self.scan_angle_deg, order);
        pick(&mut self.gps_time, order);
        pick(&mut self.point_source_id, order);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permuting_in_place_equals_the_permuted_copy_also_for_a_subset() {
        let n = 7;
        let p = AlsPoints {
            x: (0..n).map(|i| i as f64).collect(),
            y: (0..n).map(|i| 10.0 + i as f64).collect(),
            z: (0..n).map(|i| 20.0 + i as f64).collect(),
            intensity: (0..n).map(|i| 100 + i as u16).collect(),
            return_number: (0..n).map(|i| 1 + (i % 3) as u8).collect(),
            number_of_returns: vec![3; n],
            classification: (0..n).map(|i| (i % 6) as u8).collect(),
            scan_angle_deg: (0..n).map(|i| -(i as f32)).collect(),
            gps_time: (0..n).map(|i| 1e6 + i as f64).collect(),
            point_source_id: (0..n).map(|i| 7 + i as u16).collect(),
        };
        for order in [vec![6u32, 0, 3, 1, 5, 2, 4], vec![4, 1], vec![]] {
            let mut q = p.clone();
            q.permute(&order);
            assert_eq!(q, p.permuted(&order));
            assert_eq!(q.len(), order.len());
            assert!(order.iter().enumerate().all(|(k, &i)| q.x[k] == i as f64 && q.gps_time[k] == 1e6 + i as f64));
        }
    }
}
