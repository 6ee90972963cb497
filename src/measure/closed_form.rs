//! The paper's closed-form location of T from the strings of anchors A, C
//! and D, equations (26)-(38), exactly as published.
//!
//! The paper's frame has its origin at A, x towards C and z normal to the
//! anchor plane; we build that frame from the anchors (the first, third and
//! fourth of rig.json, named A, C, D in the paper) and map the result back
//! to the rig frame, so a rig surveyed in another frame still works.

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Result};

/// True when the closed form's point `closed_form` is the mirror image of
/// the least-squares point `lsq` across the plane of anchors A, C and D
/// (the first, third and fourth), the plane the closed form measures its
/// z >= 0 from: the point lies below it. False with fewer than four
/// anchors, or when the two are within 1 mm.
pub fn is_paper_mirror(
    anchors: &[Vector3<f64>],
    closed_form: &Vector3<f64>,
    lsq: &Vector3<f64>,
) -> bool {
    let apart = (closed_form - lsq).norm();
    if anchors.len() < 4 || apart <= 1.0 {
        return false;
    }
    let (a, c, d) = (anchors[0], anchors[2], anchors[3]);
    let Some(n) = (c - a).cross(&(d - a)).try_normalize(1e-12) else {
        return false;
    };
    let mirror = closed_form - 2.0 * (closed_form - a).dot(&n) * n;
    (mirror - lsq).norm() < 0.1 * apart
}

/// T in the rig frame from readings `l_a, l_c, l_d` (mm) and the string
/// constant `r` (mm). `anchors` are A, B, C, D in rig.json order; B is not
/// used by the paper's equations.
pub fn paper_closed_form(
    anchors: &[Vector3<f64>],
    l_a: f64,
    l_c: f64,
    l_d: f64,
    r: f64,
) -> Result<Vector3<f64>> {
    if anchors.len() < 4 {
        return Err(Error::InsufficientData(
            "the paper's closed form needs the four anchors A, B, C, D".into(),
        ));
    }
    let (a, c, d) = (anchors[0], anchors[2], anchors[3]);
    let ex = (c - a).normalize();
    let ez = ex.cross(&(d - a)).normalize();
    let ey = ez.cross(&ex);
    let frame = Matrix3::from_columns(&[ex, ey, ez]);
    let l_ac = (c - a).norm();
    let l_ad = (d - a).norm();
    let l_cd = (d - c).norm();
    let la = l_a + r;
    let lc = l_c + r;
    let ld = l_d + r;
    // (26), (27)
    let cos_b = (la * la + l_ac * l_ac - lc * lc) / (2.0 * la * l_ac);
    let x = (la * la + l_ac * l_ac - lc * lc) / (2.0 * l_ac);
    // (28), (29)
    let cos_a = (la * la + l_ad * l_ad - ld * ld) / (2.0 * la * l_ad);
    let cos_g = (l_ad * l_ad + l_ac * l_ac - l_cd * l_cd) / (2.0 * l_ad * l_ac);
    let sin_g = (1.0 - cos_g * cos_g).sqrt();
    // (30), (31)
    let rad = sin_g * sin_g - cos_a * cos_a - cos_b * cos_b + 2.0 * cos_g * cos_a * cos_b;
    if !(rad.is_finite() && cos_b.abs() <= 1.0 && cos_a.abs() <= 1.0) {
        return Err(Error::Numerical(
            "closed form: the readings do not form a triangle".into(),
        ));
    }
    let sin_t = rad.max(0.0).sqrt() / sin_g;
    let z = la * sin_t;
    // (32)-(37)
    let tan_g = sin_g / cos_g;
    let tan_b = (1.0 - cos_b * cos_b).sqrt() / cos_b;
    let l_ce = l_ac * tan_g;
    let l_ae = (l_ac * l_ac + l_ce * l_ce).sqrt();
    let l_cf = l_ac * tan_b;
    let l_af = (l_ac * l_ac + l_cf * l_cf).sqrt();
    let l_ef = (l_af * l_af + l_ae * l_ae - 2.0 * l_ae * l_af * cos_a)
        .max(0.0)
        .sqrt();
    let cos_w = (l_ce * l_ce + l_cf * l_cf - l_ef * l_ef) / (2.0 * l_ce * l_cf);
    // (38)
    let y = cos_w.signum()
        * (la * la * (1.0 - sin_t * sin_t - cos_b * cos_b))
            .max(0.0)
            .sqrt();
    Ok(a + frame * Vector3::new(x, y, z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproduces_a_known_point() {
        let anchors = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(3.5, 898.9, 0.0),
            Vector3::new(1200.0, 0.0, 0.0),
            Vector3::new(1202.3, 900.7, 0.0),
        ];
        let r = 35.0;
        for t in [
            Vector3::new(420.0, 310.0, 555.0),
            Vector3::new(900.0, 700.0, 300.0),
            Vector3::new(300.0, -50.0, 400.0),
        ] {
            let l = |k: usize| (t - anchors[k]).norm() - r;
            let p = paper_closed_form(&anchors, l(0), l(2), l(3), r).unwrap();
            assert!((p - t).norm() < 1e-6, "{p:?} vs {t:?}");
        }
    }
}
