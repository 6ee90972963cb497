//! URDF in: a robot model from a URDF, converted exactly to robot.json's
//! DH (with Hayati's β) or Craig's MDH form.
//!
//! The chain is the path of joints from the base link (the tree's root, or
//! [`UrdfOptions::base_link`]) to the link that carries the tool point T
//! ([`UrdfOptions::tool_link`]). Fixed joints are folded into the next
//! revolute joint's origin (or into the tool point after the last one);
//! `revolute` and `continuous` joints become the robot's joints, in chain
//! order; any other joint type on the chain is refused by name.
//!
//! The conversion is exact, not fitted: at zero joint angles the converted
//! model has every joint axis on the same line, turning the same way, as
//! the URDF's, and T at the same point; by the product of exponentials a
//! serial chain is determined by exactly that, so forward kinematics agree
//! at every joint angle (tests: `cargo test --test engine urdf`). Per link
//! the common normal between consecutive axes is used (standard DH); for
//! axes within [`NEAR_PARALLEL_DEG`] of parallel, Hayati's form (`d = 0`,
//! the tilt in β) instead, so a nominally parallel pair stays well
//! conditioned. Only the first joint is constrained: DH turns it about the
//! base frame's z axis, MDH about any direction through a point on the
//! base's x'' axis; where neither holds the error names the joint.
//!
//! URDF units are metres and radians; robot.json's are mm and degrees.

use std::collections::HashMap;

use nalgebra::{Matrix3, Vector3};

use super::robot::{Convention, JointSpec, LinkMass, Robot};
use crate::error::{Error, Result};

/// Axes closer to parallel than this (deg) get Hayati's form (d = 0, the
/// tilt in β) instead of the far-off common normal.
pub const NEAR_PARALLEL_DEG: f64 = 10.0;

/// What the URDF itself does not say: where the chain starts and ends, and
/// where T sits.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UrdfOptions {
    /// The link that carries T (default: `tool0` if the URDF has it, else
    /// the chain's only tip link).
    pub tool_link: Option<String>,
    /// T in the tool link's frame (mm).
    pub tool_xyz_mm: [f64; 3],
    /// The robot's base frame (default: the tree's root link).
    pub base_link: Option<String>,
    /// Force a convention (default: DH where exact, else MDH).
    pub convention: Option<Convention>,
}

/// A rigid transform (rotation, translation in mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation.
    pub r: Matrix3<f64>,
    /// Translation (mm).
    pub p: Vector3<f64>,
}

impl Pose {
    /// The identity.
    pub fn identity() -> Self {
        Pose {
            r: Matrix3::identity(),
            p: Vector3::zeros(),
        }
    }
    /// From URDF's `xyz` (mm here) and `rpy` (rad, fixed axes: Rz Ry Rx).
    pub fn from_xyz_rpy(xyz_mm: [f64; 3], rpy_rad: [f64; 3]) -> Self {
        let [roll, pitch, yaw] = rpy_rad;
        Pose {
            r: Pose::rot(2, yaw).r * Pose::rot(1, pitch).r * Pose::rot(0, roll).r,
            p: Vector3::from(xyz_mm),
        }
    }
    /// `self * other`.
    pub fn then(&self, other: &Pose) -> Pose {
        Pose {
            r: self.r * other.r,
            p: self.r * other.p + self.p,
        }
    }
    /// The inverse transform.
    pub fn inverse(&self) -> Pose {
        let rt = self.r.transpose();
        Pose {
            r: rt,
            p: -(rt * self.p),
        }
    }
    /// Map a point.
    pub fn apply(&self, v: &Vector3<f64>) -> Vector3<f64> {
        self.r * v + self.p
    }
    fn rot(axis: usize, t: f64) -> Pose {
        let ax = [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()][axis];
        Pose {
            r: *nalgebra::Rotation3::from_axis_angle(&ax, t).matrix(),
            p: Vector3::zeros(),
        }
    }
    fn trans(axis: usize, d: f64) -> Pose {
        let mut p = Vector3::zeros();
        p[axis] = d;
        Pose {
            r: Matrix3::identity(),
            p,
        }
    }
}

/// A joint's kind, as URDF names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// `revolute`: with limits.
    Revolute,
    /// `continuous`: a revolute joint without limits.
    Continuous,
    /// `fixed`: folded into the neighbouring joints.
    Fixed,
    /// `prismatic`, `floating`, `planar`: not supported on the chain.
    Other,
}

/// One `<joint>`.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfJoint {
    /// `name`.
    pub name: String,
    /// `type` as given.
    pub type_name: String,
    /// Kind.
    pub kind: JointKind,
    /// Parent link.
    pub parent: String,
    /// Child link.
    pub child: String,
    /// `<origin>`: child frame in the parent's (mm, rad).
    pub origin: Pose,
    /// `<axis>`, unit (default x, as URDF says).
    pub axis: Vector3<f64>,
    /// `<limit lower upper>` (rad), when given.
    pub limit_rad: Option<(f64, f64)>,
    /// Whether the joint has `<mimic>`.
    pub mimic: bool,
}

/// A link's `<inertial>`: mass and centre of mass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass in the link frame (mm).
    pub com_mm: Vector3<f64>,
}

/// A parsed URDF: what the conversion reads of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Urdf {
    /// `<robot name>`.
    pub name: String,
    /// Link names, in file order, with their inertials.
    pub links: Vec<(String, Option<Inertial>)>,
    /// Joints, in file order.
    pub joints: Vec<UrdfJoint>,
}

/// True when a robot file's text looks like XML (a URDF), not JSON.
pub fn looks_like_xml(text: &str) -> bool {
    text.trim_start_matches('\u{feff}')
        .trim_start()
        .starts_with('<')
}

fn numbers<const N: usize>(field: &str, s: &str) -> Result<[f64; N]> {
    let parts: Vec<&str> = s.split_whitespace().collect();
    if parts.len() != N {
        return Err(Error::field(
            field,
            format!("{s:?}: expected {N} numbers separated by spaces"),
        ));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                let hint = if p.contains("${") {
                    " (a xacro expression: run xacro first)"
                } else {
                    ""
                };
                Error::field(field, format!("{p:?} is not a finite number{hint}"))
            })?;
    }
    Ok(out)
}

fn origin_of(node: roxmltree::Node, field: &str) -> Result<Pose> {
    match node.children().find(|c| c.has_tag_name("origin")) {
        None => Ok(Pose::identity()),
        Some(o) => {
            let xyz = match o.attribute("xyz") {
                Some(s) => numbers::<3>(&format!("{field}.origin.xyz"), s)?,
                None => [0.0; 3],
            };
            let rpy = match o.attribute("rpy") {
                Some(s) => numbers::<3>(&format!("{field}.origin.rpy"), s)?,
                None => [0.0; 3],
            };
            Ok(Pose::from_xyz_rpy(xyz.map(|v| v * 1000.0), rpy))
        }
    }
}

impl Urdf {
    /// Parse URDF text (not xacro). Errors name the element
    /// (`urdf: joint "elbow_joint".axis.xyz`).
    pub fn parse(text: &str) -> Result<Urdf> {
        let doc = roxmltree::Document::parse(text.trim_start_matches('\u{feff}'))
            .map_err(|e| Error::field("urdf", format!("not well-formed XML: {e}")))?;
        let root = doc.root_element();
        if !root.has_tag_name("robot") {
            return Err(Error::field(
                "urdf",
                format!(
                    "the root element is <{}>, a URDF's is <robot>",
                    root.tag_name().name()
                ),
            ));
        }
        let mut links = Vec::new();
        let mut joints = Vec::new();
        for n in root.children().filter(|n| n.is_element()) {
            if n.tag_name()
                .namespace()
                .is_some_and(|ns| ns.contains("xacro"))
            {
                return Err(Error::field(
                    "urdf",
                    format!(
                        "<xacro:{}>: this is a xacro file; run `xacro` to expand it into a URDF first",
                        n.tag_name().name()
                    ),
                ));
            }
            match n.tag_name().name() {
                "link" => {
                    let name = n
                        .attribute("name")
                        .ok_or_else(|| Error::field("urdf: link", "a <link> without a name"))?
                        .to_string();
                    let field = format!("urdf: link {name:?}");
                    let inertial = match n.children().find(|c| c.has_tag_name("inertial")) {
                        None => None,
                        Some(i) => {
                            let mass = i
                                .children()
                                .find(|c| c.has_tag_name("mass"))
                                .and_then(|m| m.attribute("value"))
                                .ok_or_else(|| {
                                    Error::field(
                                        format!("{field}.inertial.mass"),
                                        "an <inertial> needs <mass value=...>",
                                    )
                                })?;
                            let [mass_kg] = numbers::<1>(&format!("{field}.inertial.mass"), mass)?;
                            if mass_kg < 0.0 {
                                return Err(Error::field(
                                    format!("{field}.inertial.mass"),
                                    "must be >= 0",
                                ));
                            }
                            let o = origin_of(i, &format!("{field}.inertial"))?;
                            Some(Inertial {
                                mass_kg,
                                com_mm: o.p,
                            })
                        }
                    };
                    links.push((name, inertial));
                }
                "joint" => joints.push(Self::joint(n)?),
                _ => {}
            }
        }
        let urdf = Urdf {
            name: root.attribute("name").unwrap_or("").to_string(),
            links,
            joints,
        };
        urdf.check_tree()?;
        Ok(urdf)
    }

    fn joint(n: roxmltree::Node) -> Result<UrdfJoint> {
        let name = n
            .attribute("name")
            .ok_or_else(|| Error::field("urdf: joint", "a <joint> without a name"))?
            .to_string();
        let field = format!("urdf: joint {name:?}");
        let type_name = n
            .attribute("type")
            .ok_or_else(|| Error::field(format!("{field}.type"), "missing"))?
            .to_string();
        let kind = match type_name.as_str() {
            "revolute" => JointKind::Revolute,
            "continuous" => JointKind::Continuous,
            "fixed" => JointKind::Fixed,
            "prismatic" | "floating" | "planar" => JointKind::Other,
            t => {
                return Err(Error::field(
                    format!("{field}.type"),
                    format!("{t:?} is not a URDF joint type"),
                ));
            }
        };
        let link_of = |tag: &str| -> Result<String> {
            n.children()
                .find(|c| c.has_tag_name(tag))
                .and_then(|c| c.attribute("link"))
                .map(str::to_string)
                .ok_or_else(|| Error::field(format!("{field}.{tag}"), "missing <{tag} link=...>"))
        };
        let axis = match n
            .children()
            .find(|c| c.has_tag_name("axis"))
            .and_then(|a| a.attribute("xyz"))
        {
            Some(s) => {
                let v = Vector3::from(numbers::<3>(&format!("{field}.axis.xyz"), s)?);
                if v.norm() < 1e-12 {
                    return Err(Error::field(format!("{field}.axis.xyz"), "a zero axis"));
                }
                v.normalize()
            }
            None => Vector3::x(),
        };
        let limit_rad = match n.children().find(|c| c.has_tag_name("limit")) {
            Some(l) if kind == JointKind::Revolute => {
                let get = |a: &str| -> Result<f64> {
                    match l.attribute(a) {
                        Some(s) => Ok(numbers::<1>(&format!("{field}.limit.{a}"), s)?[0]),
                        None => Ok(0.0),
                    }
                };
                let (lo, hi) = (get("lower")?, get("upper")?);
                if lo >= hi {
                    return Err(Error::field(
                        format!("{field}.limit"),
                        format!("lower {lo} must be below upper {hi}"),
                    ));
                }
                Some((lo, hi))
            }
            _ => None,
        };
        Ok(UrdfJoint {
            origin: origin_of(n, &field)?,
            parent: link_of("parent")?,
            child: link_of("child")?,
            name,
            type_name,
            kind,
            axis,
            limit_rad,
            mimic: n.children().any(|c| c.has_tag_name("mimic")),
        })
    }

    fn check_tree(&self) -> Result<()> {
        let mut parent_of: HashMap<&str, &str> = HashMap::new();
        for j in &self.joints {
            for l in [&j.parent, &j.child] {
                if !self.links.iter().any(|(n, _)| n == l) {
                    return Err(Error::field(
                        format!("urdf: joint {:?}", j.name),
                        format!("link {l:?} is not defined"),
                    ));
                }
            }
            if parent_of.insert(&j.child, &j.parent).is_some() {
                return Err(Error::field(
                    format!("urdf: joint {:?}", j.name),
                    format!("link {:?} has two parent joints", j.child),
                ));
            }
        }
        Ok(())
    }

    /// The tree's root link (the one link no joint is the child of).
    pub fn root(&self) -> Result<&str> {
        let roots: Vec<&str> = self
            .links
            .iter()
            .map(|(n, _)| n.as_str())
            .filter(|n| !self.joints.iter().any(|j| j.child == *n))
            .collect();
        match roots.as_slice() {
            [r] => Ok(r),
            [] => Err(Error::field(
                "urdf",
                "no root link (the joints form a loop)",
            )),
            _ => Err(Error::field(
                "urdf",
                format!(
                    "{} root links ({}): a URDF is one tree",
                    roots.len(),
                    roots.join(", ")
                ),
            )),
        }
    }

    fn has_link(&self, name: &str) -> bool {
        self.links.iter().any(|(n, _)| n == name)
    }

    /// The joints from `base` to `tip`, base first.
    pub fn chain(&self, base: &str, tip: &str) -> Result<Vec<&UrdfJoint>> {
        for (opt, l) in [("base_link", base), ("tool_link", tip)] {
            if !self.has_link(l) {
                let names: Vec<&str> = self.links.iter().map(|(n, _)| n.as_str()).collect();
                return Err(Error::field(
                    opt,
                    format!(
                        "{l:?} is not a link of this URDF; its links are {}",
                        names.join(", ")
                    ),
                ));
            }
        }
        let mut out = Vec::new();
        let mut at = tip;
        while at != base {
            let Some(j) = self.joints.iter().find(|j| j.child == at) else {
                return Err(Error::field(
                    "tool_link",
                    format!("{tip:?} is not below base link {base:?} in the URDF's tree"),
                ));
            };
            out.push(j);
            at = &j.parent;
        }
        out.reverse();
        Ok(out)
    }

    /// The default tool link: `tool0` if there is one, else the only leaf.
    fn default_tool(&self) -> Result<String> {
        if self.has_link("tool0") {
            return Ok("tool0".into());
        }
        let leaves: Vec<&str> = self
            .links
            .iter()
            .map(|(n, _)| n.as_str())
            .filter(|n| !self.joints.iter().any(|j| j.parent == *n))
            .collect();
        match leaves.as_slice() {
            [l] => Ok(l.to_string()),
            _ => Err(Error::field(
                "tool_link",
                format!(
                    "name the link that carries T (the tip links are {})",
                    leaves.join(", ")
                ),
            )),
        }
    }
}

/// The URDF's own forward kinematics of a chain (from [`Urdf::chain`]): the
/// tip link's frame in the base link's at joint angles `q_rad` (one per
/// revolute or continuous joint, in chain order). Plain transform products,
/// independent of the DH conversion.
pub fn chain_fk(chain: &[&UrdfJoint], q_rad: &[f64]) -> Pose {
    let mut f = Pose::identity();
    let mut k = 0;
    for j in chain {
        f = f.then(&j.origin);
        if matches!(j.kind, JointKind::Revolute | JointKind::Continuous) {
            let ax = nalgebra::Unit::new_normalize(j.axis);
            f = f.then(&Pose {
                r: *nalgebra::Rotation3::from_axis_angle(&ax, q_rad[k]).matrix(),
                p: Vector3::zeros(),
            });
            k += 1;
        }
    }
    f
}

/// A robot model from URDF text: parse, take the chain, convert exactly
/// (module docs). `options.tool_xyz_mm` is T in the tool link's frame.
pub fn robot_from_urdf(text: &str, options: &UrdfOptions) -> Result<Robot> {
    let urdf = Urdf::parse(text)?;
    urdf.to_robot(options)
}

/// A robot file's text as a model: a URDF (when `urdf` is set, e.g. by a
/// `.urdf` file name, or when the text starts with `<`) converted with
/// `options`, else robot.json. The one rule the CLI's `--robot` and the
/// service's `POST /models` share.
pub fn robot_from_text(text: &str, urdf: bool, options: &UrdfOptions) -> Result<Robot> {
    if urdf || looks_like_xml(text) {
        robot_from_urdf(text, options)
    } else {
        Robot::from_json(text)
    }
}

/// `tool_xyz_mm` as the command line and the query string write it:
/// three numbers separated by commas (`0,0,100`).
pub fn parse_xyz_mm(field: &str, s: &str) -> Result<[f64; 3]> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(Error::field(
            field,
            format!("{s:?}: expected three numbers separated by commas (x,y,z in mm)"),
        ));
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && v.abs() <= super::MAX_LENGTH_MM)
            .ok_or_else(|| Error::field(field, format!("{p:?} is not a length in mm")))?;
    }
    Ok(out)
}

/// An axis line at zero joint angles, in the base frame.
#[derive(Debug, Clone, Copy)]
struct Axis {
    p: Vector3<f64>,
    u: Vector3<f64>,
}

/// Feet of the common normal of two lines (point, unit direction); `None`
/// when they are parallel.
fn common_normal(a: &Axis, b: &Axis) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let w0 = a.p - b.p;
    let c = a.u.dot(&b.u);
    let den = 1.0 - c * c;
    if den < 1e-24 {
        return None;
    }
    let (da, db) = (a.u.dot(&w0), b.u.dot(&w0));
    let sa = (c * db - da) / den;
    let sb = (db - c * da) / den;
    Some((a.p + sa * a.u, b.p + sb * b.u))
}

/// Angle of `v` about `f`'s z from `f`'s x, with `v` along x or -x preferred
/// so that θ lies in (-90°, 90°]: returns (θ, sign) where the direction
/// used is `sign * v`.
fn angle_in(f: &Pose, v: &Vector3<f64>) -> (f64, f64) {
    let x = f.r.column(0).dot(v);
    let y = f.r.column(1).dot(v);
    let mut t = y.atan2(x);
    let mut s = 1.0;
    let half = std::f64::consts::FRAC_PI_2;
    if t > half + 1e-12 {
        t -= std::f64::consts::PI;
        s = -1.0;
    } else if t <= -half + 1e-12 {
        t += std::f64::consts::PI;
        s = -1.0;
    }
    (t, s)
}

/// α and β with `Rx(α) Ry(β) z = u` (u in the frame's own coordinates).
fn alpha_beta(u: &Vector3<f64>) -> (f64, f64) {
    let beta = u.x.clamp(-1.0, 1.0).asin();
    let alpha = (-u.y).atan2(u.z);
    (alpha, beta)
}

/// The DH link transform from its five parameters (mm, rad; q = 0).
fn dh_link(a: f64, alpha: f64, d: f64, theta: f64, beta: f64) -> Pose {
    Pose::rot(2, theta)
        .then(&Pose::trans(2, d))
        .then(&Pose::trans(0, a))
        .then(&Pose::rot(0, alpha))
        .then(&Pose::rot(1, beta))
}

/// Within this (mm, and rad for directions) an axis is where a form needs it.
const EXACT_MM: f64 = 1e-10;
const EXACT_RAD: f64 = 1e-13;

/// The five parameters of a joint (mm, rad) while converting.
#[derive(Debug, Clone, Copy, Default)]
struct Link {
    a: f64,
    alpha: f64,
    d: f64,
    theta: f64,
    beta: f64,
}

impl Urdf {
    /// Convert to a robot model (module docs).
    pub fn to_robot(&self, options: &UrdfOptions) -> Result<Robot> {
        let base = match &options.base_link {
            Some(b) => b.clone(),
            None => self.root()?.to_string(),
        };
        let tool = match &options.tool_link {
            Some(t) => t.clone(),
            None => self.default_tool()?,
        };
        for (k, v) in options.tool_xyz_mm.iter().enumerate() {
            if !v.is_finite() {
                return Err(Error::field(format!("tool_xyz_mm[{k}]"), "must be finite"));
            }
        }
        let chain = self.chain(&base, &tool)?;
        // Walk at q = 0: each moving joint's axis line, the masses of the
        // links each one carries, the tool frame.
        let mut w = Pose::identity();
        let mut axes = Vec::new();
        let mut specs: Vec<(f64, f64)> = Vec::new();
        let mut masses: Vec<(f64, Vector3<f64>)> = Vec::new();
        let mut any_inertial = false;
        for j in &chain {
            let field = format!("urdf: joint {:?}", j.name);
            match j.kind {
                JointKind::Other => {
                    return Err(Error::field(
                        field,
                        format!(
                            "a {} joint on the chain from {base:?} to {tool:?}: drawcal models revolute joints only",
                            j.type_name
                        ),
                    ));
                }
                JointKind::Revolute | JointKind::Continuous if j.mimic => {
                    return Err(Error::field(
                        field,
                        "a mimic joint on the chain: drawcal models independent joints only",
                    ));
                }
                _ => {}
            }
            w = w.then(&j.origin);
            if j.kind != JointKind::Fixed {
                axes.push((
                    j.name.clone(),
                    Axis {
                        p: w.p,
                        u: (w.r * j.axis).normalize(),
                    },
                ));
                specs.push(j.limit_rad.map_or((-360.0, 360.0), |(lo, hi)| {
                    (lo.to_degrees(), hi.to_degrees())
                }));
                masses.push((0.0, Vector3::zeros()));
            }
            if let Some(Some(i)) = self.links.iter().find(|(n, _)| *n == j.child).map(|l| l.1)
                && let Some(m) = masses.last_mut()
            {
                any_inertial = true;
                let c = w.apply(&i.com_mm);
                let total = m.0 + i.mass_kg;
                if total > 0.0 {
                    m.1 = (m.1 * m.0 + c * i.mass_kg) / total;
                }
                m.0 = total;
            }
        }
        if axes.is_empty() {
            return Err(Error::field(
                "urdf",
                format!("no revolute joint between {base:?} and {tool:?}"),
            ));
        }
        if axes.len() > 12 {
            return Err(Error::field(
                "urdf",
                format!("{} revolute joints: at most 12 are supported", axes.len()),
            ));
        }
        let t0 = w.apply(&Vector3::from(options.tool_xyz_mm));
        let lines: Vec<Axis> = axes.iter().map(|a| a.1).collect();
        let (convention, links, frames) = match options.convention {
            Some(Convention::Dh) => {
                let (l, f) = to_dh(&lines, &w).map_err(|m| first_joint(&axes[0].0, &base, m))?;
                (Convention::Dh, l, f)
            }
            Some(Convention::Mdh) => {
                let (l, f) = to_mdh(&lines, &w).map_err(|m| first_joint(&axes[0].0, &base, m))?;
                (Convention::Mdh, l, f)
            }
            None => match to_dh(&lines, &w) {
                Ok((l, f)) => (Convention::Dh, l, f),
                Err(dh) => match to_mdh(&lines, &w) {
                    Ok((l, f)) => (Convention::Mdh, l, f),
                    Err(mdh) => {
                        return Err(first_joint(
                            &axes[0].0,
                            &base,
                            format!("no exact DH form ({dh}) and no exact MDH form ({mdh})"),
                        ));
                    }
                },
            },
        };
        let flange = frames[frames.len() - 1];
        let tool_point = flange.inverse().apply(&t0);
        let joints = links
            .iter()
            .zip(&specs)
            .map(|(l, (lo, hi))| JointSpec {
                a_mm: l.a,
                alpha_deg: l.alpha.to_degrees(),
                d_mm: l.d,
                theta_offset_deg: l.theta.to_degrees(),
                beta_deg: l.beta.to_degrees(),
                q_min_deg: *lo,
                q_max_deg: *hi,
            })
            .collect();
        let link_masses = any_inertial.then(|| {
            masses
                .iter()
                .zip(&frames)
                .map(|((m, c), f)| LinkMass {
                    mass_kg: *m,
                    com_mm: if *m > 0.0 {
                        f.inverse().apply(c).into()
                    } else {
                        [0.0; 3]
                    },
                })
                .collect()
        });
        let robot = Robot {
            name: self.name.clone(),
            convention,
            joints,
            tool_point_mm: tool_point.into(),
            // URDF's world is z up (REP 103): gravity along -z of the base.
            gravity_in_base: any_inertial.then_some([0.0, 0.0, -9.81]),
            links: link_masses,
        };
        robot.validate()?;
        self_check(&robot, &chain, &options.tool_xyz_mm)?;
        Ok(robot)
    }
}

fn first_joint(name: &str, base: &str, why: String) -> Error {
    Error::field(
        format!("urdf: joint {name:?}"),
        format!(
            "the first joint's axis, seen from base link {base:?}, has {why}; name another base_link (one whose frame has this axis as its z axis, or its x-z plane through it), or add a fixed joint to such a frame"
        ),
    )
}

/// The converted model's T against the URDF's at a few joint angles: a
/// guard on the construction (the tests check 1e-9 mm at random angles
/// with `kinematics::Chain`; here the link transforms are multiplied out).
fn self_check(robot: &Robot, chain: &[&UrdfJoint], tool_xyz_mm: &[f64; 3]) -> Result<()> {
    let mut rng = crate::rng::Rng::new(19);
    let tool = Vector3::from(*tool_xyz_mm);
    for _ in 0..4 {
        let q: Vec<f64> = (0..robot.dof()).map(|_| rng.range(-3.0, 3.0)).collect();
        let mut f = Pose::identity();
        for (j, qj) in robot.joints.iter().zip(&q) {
            let (a, al, d) = (j.a_mm, j.alpha_deg.to_radians(), j.d_mm);
            let (th, be) = (
                j.theta_offset_deg.to_radians() + qj,
                j.beta_deg.to_radians(),
            );
            f = f.then(&match robot.convention {
                Convention::Dh => dh_link(a, al, d, th, be),
                Convention::Mdh => Pose::rot(0, al)
                    .then(&Pose::rot(1, be))
                    .then(&Pose::trans(0, a))
                    .then(&Pose::rot(2, th))
                    .then(&Pose::trans(2, d)),
            });
        }
        let ours = f.apply(&Vector3::from(robot.tool_point_mm));
        let theirs = chain_fk(chain, &q).apply(&tool);
        let e = (ours - theirs).norm();
        if e > 1e-6 * (1.0 + theirs.norm()) {
            return Err(Error::Numerical(format!(
                "the URDF's conversion misses its forward kinematics by {e:.3e} mm"
            )));
        }
    }
    Ok(())
}

/// DH with β: frame i-1 has z along axis i, origin on it; the base frame
/// is frame 0, so axis 1 must be its z axis. Returns the links and frames
/// 1..n (q = 0), frame n placed at the tool frame `tool` where it can be.
fn to_dh(axes: &[Axis], tool: &Pose) -> std::result::Result<(Vec<Link>, Vec<Pose>), String> {
    let a1 = &axes[0];
    if (a1.u - Vector3::z()).norm() > EXACT_RAD {
        return Err(format!(
            "direction ({:.6}, {:.6}, {:.6}) where DH needs +z",
            a1.u.x, a1.u.y, a1.u.z
        ));
    }
    let off = a1.p.xy().norm();
    if off > EXACT_MM {
        return Err(format!(
            "an offset of {off:.6} mm from the z axis, which DH needs it on"
        ));
    }
    let n = axes.len();
    let mut f = Pose::identity();
    let mut links = Vec::with_capacity(n);
    let mut frames = Vec::with_capacity(n);
    let near = NEAR_PARALLEL_DEG.to_radians().sin();
    for i in 0..n {
        let z = f.r.column(2).into_owned();
        let (origin, dir) = if i + 1 < n {
            let next = &axes[i + 1];
            let here = Axis { p: f.p, u: z };
            let o = match common_normal(&here, next) {
                Some((_, foot)) if z.cross(&next.u).norm() >= near => foot,
                // Hayati: where the next axis meets the plane through this
                // frame's origin normal to z (d = 0).
                _ => next.p + next.u * (-(next.p - f.p).dot(&z) / next.u.dot(&z)),
            };
            (o, next.u)
        } else {
            (tool.p, tool.r.column(2).into_owned())
        };
        let rel = origin - f.p;
        let d = rel.dot(&z);
        let radial = rel - d * z;
        let (theta, a) = if radial.norm() > EXACT_MM {
            let (t, s) = angle_in(&f, &radial);
            (t, s * radial.norm())
        } else {
            // On the axis: x along the common perpendicular of the two
            // directions (standard DH), else towards the tool frame's x.
            let cross = z.cross(&dir);
            let x = if cross.norm() > 1e-9 {
                cross
            } else if i + 1 == n {
                let tx = tool.r.column(0).into_owned();
                tx - tx.dot(&z) * z
            } else {
                f.r.column(0).into_owned()
            };
            if x.norm() > 1e-9 {
                (angle_in(&f, &x).0, 0.0)
            } else {
                (0.0, 0.0)
            }
        };
        let mid = f
            .then(&Pose::rot(2, theta))
            .then(&Pose::trans(2, d))
            .then(&Pose::trans(0, a));
        let (alpha, beta) = alpha_beta(&(mid.r.transpose() * dir));
        let link = Link {
            a,
            alpha,
            d,
            theta,
            beta,
        };
        f = f.then(&dh_link(a, alpha, d, theta, beta));
        links.push(link);
        frames.push(f);
    }
    Ok((links, frames))
}

/// Craig's MDH with β: frame i has z along axis i, origin on it; link i is
/// `Rx(α) Ry(β) Tx(a)` from frame i-1, then `Rz(θ) Tz(d)` along axis i.
fn to_mdh(axes: &[Axis], tool: &Pose) -> std::result::Result<(Vec<Link>, Vec<Pose>), String> {
    let n = axes.len();
    let near = NEAR_PARALLEL_DEG.to_radians().sin();
    let mut links = vec![Link::default(); n];
    // Joint 1 from the base frame: its direction gives α, β; the foot of
    // the axis from the origin must lie along the rotated x.
    let a1 = &axes[0];
    let (alpha, beta) = alpha_beta(&a1.u);
    let rot = Pose::rot(0, alpha).then(&Pose::rot(1, beta));
    let (x2, y2) = (rot.r.column(0).into_owned(), rot.r.column(1).into_owned());
    let foot = a1.p - a1.p.dot(&a1.u) * a1.u;
    if foot.dot(&y2).abs() > EXACT_MM {
        return Err(format!(
            "a foot {:.6} mm off the plane MDH needs it in",
            foot.dot(&y2)
        ));
    }
    links[0].alpha = alpha;
    links[0].beta = beta;
    links[0].a = foot.dot(&x2);
    // e: frame i before its Rz(θ) Tz(d).
    let mut e = rot.then(&Pose::trans(0, links[0].a));
    let mut frames = Vec::with_capacity(n);
    for i in 0..n {
        let z = e.r.column(2).into_owned();
        if i + 1 == n {
            let d = (tool.p - e.p).dot(&z);
            let tx = tool.r.column(0).into_owned();
            let x = tx - tx.dot(&z) * z;
            let theta = if x.norm() > 1e-9 {
                let x0 = e.r.column(0).dot(&x);
                e.r.column(1).dot(&x).atan2(x0)
            } else {
                0.0
            };
            links[i].theta = theta;
            links[i].d = d;
            frames.push(e.then(&Pose::rot(2, theta)).then(&Pose::trans(2, d)));
            break;
        }
        let next = &axes[i + 1];
        let here = Axis { p: e.p, u: z };
        let (d, theta, link) = match common_normal(&here, next) {
            Some((c1, c2)) if z.cross(&next.u).norm() >= near => {
                let d = (c1 - e.p).dot(&z);
                let nrm = c2 - c1;
                let dir = if nrm.norm() > EXACT_MM {
                    nrm
                } else {
                    z.cross(&next.u)
                };
                let (theta, s) = angle_in(&e, &dir);
                let f = e.then(&Pose::rot(2, theta)).then(&Pose::trans(2, d));
                let (alpha, beta) = alpha_beta(&(f.r.transpose() * next.u));
                let a = if nrm.norm() > EXACT_MM {
                    s * nrm.norm()
                } else {
                    0.0
                };
                (d, theta, (alpha, beta, a))
            }
            _ => {
                // Hayati: d = 0; x turned so that the foot of the next
                // axis lies along the tilted x.
                let u = next.u;
                let mut fv = (next.p - e.p) - (next.p - e.p).dot(&u) * u;
                if fv.norm() < EXACT_MM {
                    let ex = e.r.column(0).into_owned();
                    fv = ex - ex.dot(&u) * u;
                }
                let w = u.cross(&fv.normalize());
                let x = z.cross(&w);
                let (theta, _) = angle_in(&e, &x);
                let f = e.then(&Pose::rot(2, theta));
                let (alpha, beta) = alpha_beta(&(f.r.transpose() * u));
                let tilt = f.then(&Pose::rot(0, alpha)).then(&Pose::rot(1, beta));
                let foot = (next.p - f.p) - (next.p - f.p).dot(&u) * u;
                (0.0, theta, (alpha, beta, foot.dot(&tilt.r.column(0))))
            }
        };
        links[i].d = d;
        links[i].theta = theta;
        let f = e.then(&Pose::rot(2, theta)).then(&Pose::trans(2, d));
        frames.push(f);
        let (alpha, beta, a) = link;
        links[i + 1].alpha = alpha;
        links[i + 1].beta = beta;
        links[i + 1].a = a;
        e = f
            .then(&Pose::rot(0, alpha))
            .then(&Pose::rot(1, beta))
            .then(&Pose::trans(0, a));
    }
    Ok((links, frames))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_xacro_and_names_prismatic_joints() {
        let x = r#"<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:macro name="m"/></robot>"#;
        let e = Urdf::parse(x).unwrap_err().to_string();
        assert!(e.contains("xacro"), "{e}");
        let p = r#"<robot name="r"><link name="a"/><link name="b"/>
            <joint name="slide" type="prismatic"><parent link="a"/><child link="b"/></joint></robot>"#;
        let e = robot_from_urdf(p, &UrdfOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"slide\"") && e.contains("prismatic"), "{e}");
    }
}
