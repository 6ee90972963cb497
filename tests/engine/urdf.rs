//! URDF in (issue 19, item 2): the test URDFs under tests/data/urdf
//! converted to robot.json's DH/MDH form, their forward kinematics against
//! the URDF's own (plain transform products) at random joint angles.

use drawcal::kinematics::chain::OutputFrame;
use drawcal::kinematics::{Chain, Params};
use drawcal::model::urdf::{Urdf, UrdfOptions, chain_fk, robot_from_urdf};
use drawcal::model::{Convention, Robot};
use drawcal::rng::Rng;
use nalgebra::Vector3;

use super::common;

fn text(name: &str) -> String {
    std::fs::read_to_string(common::dir("urdf").join(name)).unwrap()
}

fn options(tool: &str, xyz: [f64; 3]) -> UrdfOptions {
    UrdfOptions {
        tool_link: Some(tool.into()),
        tool_xyz_mm: xyz,
        ..Default::default()
    }
}

/// The largest distance (mm) between T of the converted model and T of the
/// URDF over `n` random joint vectors within the limits; also checks the
/// link masses' centres of mass.
fn worst_fk_error(urdf_text: &str, opt: &UrdfOptions, n: usize) -> (Robot, f64) {
    let robot = robot_from_urdf(urdf_text, opt).unwrap();
    let urdf = Urdf::parse(urdf_text).unwrap();
    let base = opt
        .base_link
        .clone()
        .unwrap_or_else(|| urdf.root().unwrap().to_string());
    let chain = urdf
        .chain(&base, opt.tool_link.as_deref().unwrap_or("tool0"))
        .unwrap();
    let p = Params::of_robot(&robot);
    let c = Chain::new(robot.convention, robot.dof(), 0);
    let mut rng = Rng::new(7);
    let mut worst: f64 = 0.0;
    for _ in 0..n {
        let q: Vec<f64> = robot
            .joints
            .iter()
            .map(|j| {
                rng.range(j.q_min_deg.max(-360.0), j.q_max_deg.min(360.0))
                    .to_radians()
            })
            .collect();
        let (_, ours) = c.point(&p.values, &q, OutputFrame::Base);
        let theirs = chain_fk(&chain, &q).apply(&Vector3::from(opt.tool_xyz_mm));
        worst = worst.max((ours - theirs).norm());
        // Centres of mass: each URDF link's, weighted, per moving segment.
        if let Some(links) = &robot.links {
            let frames = c.link_frames(&p.values, &q, OutputFrame::Base);
            let mut seg: Vec<(f64, Vector3<f64>)> = vec![(0.0, Vector3::zeros()); robot.dof()];
            let mut k: Option<usize> = None;
            for (i, j) in chain.iter().enumerate() {
                if j.type_name != "fixed" {
                    k = Some(k.map_or(0, |k| k + 1));
                }
                let inertial = urdf.links.iter().find(|l| l.0 == j.child).unwrap().1;
                if let (Some(k), Some(inr)) = (k, inertial) {
                    let nq = chain[..=i]
                        .iter()
                        .filter(|j| j.type_name != "fixed")
                        .count();
                    let c = chain_fk(&chain[..=i], &q[..nq]).apply(&inr.com_mm);
                    seg[k].0 += inr.mass_kg;
                    seg[k].1 += c * inr.mass_kg;
                }
            }
            for (k, (m, mc)) in seg.iter().enumerate() {
                assert!((links[k].mass_kg - m).abs() < 1e-12);
                if *m > 0.0 {
                    let ours = frames[k].apply(&Vector3::from(links[k].com_mm));
                    let e = (ours - mc / *m).norm();
                    assert!(e < 1e-9, "link {} centre of mass off by {e:e} mm", k + 1);
                }
            }
        }
    }
    (robot, worst)
}

#[test]
fn urdf_ur5_ur10_and_industrial_arm_convert_exactly() {
    for (file, conv) in [
        ("ur5.urdf", Convention::Dh),
        ("ur10.urdf", Convention::Dh),
        ("industrial6.urdf", Convention::Dh),
    ] {
        for xyz in [[0.0; 3], [0.0, 0.0, 100.0], [12.0, -30.0, 85.0]] {
            let (robot, worst) = worst_fk_error(&text(file), &options("tool0", xyz), 300);
            assert_eq!(robot.convention, conv, "{file}");
            assert_eq!(robot.dof(), 6);
            assert!(worst < 1e-9, "{file} {xyz:?}: FK differs by {worst:e} mm");
            assert!(robot.links.is_some() && robot.gravity_in_base.is_some());
        }
    }
}

#[test]
fn urdf_ur5_gives_the_published_dh_table() {
    // tests/data/ur5_geometric/robot.json is UR's published DH table; the
    // URDF's base_link is turned 180 deg from the DH base (base_link_inertia),
    // which is where the table's frame 0 is.
    let mut o = options("tool0", [0.0; 3]);
    o.base_link = Some("base_link_inertia".into());
    let robot = robot_from_urdf(&text("ur5.urdf"), &o).unwrap();
    let published = common::load("ur5_geometric").0;
    for (i, (a, b)) in robot.joints.iter().zip(&published.joints).enumerate() {
        for (what, x, y) in [
            ("a_mm", a.a_mm, b.a_mm),
            ("alpha_deg", a.alpha_deg, b.alpha_deg),
            ("d_mm", a.d_mm, b.d_mm),
            ("beta_deg", a.beta_deg, b.beta_deg),
            ("theta_offset_deg", a.theta_offset_deg, b.theta_offset_deg),
        ] {
            assert!((x - y).abs() < 1e-6, "joint {} {what}: {x} vs {y}", i + 1);
        }
    }
    assert!((robot.joints[0].q_max_deg - 360.0).abs() < 1e-9);
    assert!((robot.joints[2].q_max_deg - 180.0).abs() < 1e-9);
}

#[test]
fn urdf_tilted_axis_uses_beta() {
    let robot = robot_from_urdf(&text("industrial6.urdf"), &options("tool0", [0.0; 3])).unwrap();
    // joint_3's axis is 0.5 deg off parallel to joint_2's: Hayati's form, d = 0.
    let j2 = &robot.joints[1];
    assert!(
        (j2.beta_deg.abs() - 0.5).abs() < 0.01 || (j2.alpha_deg.abs() - 0.5).abs() < 0.01,
        "{j2:?}"
    );
    assert!(
        j2.d_mm.abs() < 1e-9 && (j2.a_mm.abs() - 600.0).abs() < 1.0,
        "{j2:?}"
    );
    assert!(
        robot
            .joints
            .iter()
            .all(|j| j.d_mm.abs() < 2000.0 && j.a_mm.abs() < 2000.0)
    );
}

#[test]
fn urdf_first_axis_off_z_falls_back_to_mdh_or_is_refused_by_name() {
    let base = text("industrial6.urdf");
    let j1 = r#"<origin xyz="0 0 0.45" rpy="0 0 0"/><axis xyz="0 0 1"/>"#;
    assert!(base.contains(j1));
    // Turning the other way (KUKA's joint a1) and off the base's z axis
    // along x: no DH form, an exact MDH one.
    for variant in [
        r#"<origin xyz="0 0 0.45" rpy="0 0 0"/><axis xyz="0 0 -1"/>"#,
        r#"<origin xyz="0.1 0 0.45" rpy="0 0 0"/><axis xyz="0 0 1"/>"#,
        r#"<origin xyz="0.1 0 0.45" rpy="0 0.2 0"/><axis xyz="0 0 1"/>"#,
    ] {
        let t = base.replace(j1, variant);
        let (robot, worst) = worst_fk_error(&t, &options("tool0", [5.0, 0.0, 50.0]), 200);
        assert_eq!(robot.convention, Convention::Mdh, "{variant}");
        assert!(worst < 1e-9, "{variant}: FK differs by {worst:e} mm");
        // Forcing DH names the joint and says why.
        let mut o = options("tool0", [0.0; 3]);
        o.convention = Some(Convention::Dh);
        let e = robot_from_urdf(&t, &o).unwrap_err().to_string();
        assert!(e.contains("\"joint_1\"") && e.contains("DH"), "{e}");
    }
    // MDH forced on the arm DH takes: exact too.
    let mut o = options("tool0", [0.0, 0.0, 100.0]);
    o.convention = Some(Convention::Mdh);
    let (robot, worst) = worst_fk_error(&base, &o, 200);
    assert_eq!(robot.convention, Convention::Mdh);
    assert!(worst < 1e-9, "MDH: {worst:e} mm");
    // Off the base's z axis sideways (y): neither form, refused by name.
    let t = base.replace(
        j1,
        r#"<origin xyz="0 0.1 0.45" rpy="0 0 0"/><axis xyz="0 0 1"/>"#,
    );
    let e = robot_from_urdf(&t, &options("tool0", [0.0; 3]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("\"joint_1\"") && e.contains("no exact DH form") && e.contains("MDH"),
        "{e}"
    );
}

#[test]
fn urdf_options_and_errors_name_what_is_wrong() {
    let t = text("ur5.urdf");
    let e = robot_from_urdf(&t, &options("tool9", [0.0; 3]))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("tool_link") && e.contains("tool9") && e.contains("wrist_3_link"),
        "{e}"
    );
    // Default tool link: tool0. A base link partway up the arm: fewer joints.
    let r = robot_from_urdf(&t, &UrdfOptions::default()).unwrap();
    assert_eq!(r.dof(), 6);
    let mut o = options("tool0", [0.0; 3]);
    o.base_link = Some("upper_arm_link".into());
    let (r, worst) = worst_fk_error(&t, &o, 50);
    assert_eq!(r.dof(), 4);
    assert!(worst < 1e-9);
    let e = robot_from_urdf(
        &t.replace("0 -0.09465", "0 ${-d5}"),
        &UrdfOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("wrist_2_joint") && e.contains("xacro"), "{e}");
    let e = robot_from_urdf("{\"joints\": []}", &UrdfOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("XML"), "{e}");
}

/// The README's ER3A URDF is the ER3A of robot.json: the same T at random
/// angles (tool point 0,0,60 mm on the flange), so a plan made from either
/// is the same session.
#[test]
fn urdf_er3a_is_the_er3a_robot_json() {
    let (robot, worst) = worst_fk_error(
        &text("er3a.urdf"),
        &options("flange", [0.0, 0.0, 60.0]),
        100,
    );
    assert!(worst < 1e-9, "{worst}");
    let json = Robot::from_json(
        &std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/data/er3a_paper_like/robot.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let (a, b) = (Params::of_robot(&robot), Params::of_robot(&json));
    let (ca, cb) = (
        Chain::new(robot.convention, 6, 0),
        Chain::new(json.convention, 6, 0),
    );
    let mut rng = drawcal::rng::Rng::new(4);
    for _ in 0..200 {
        let q: Vec<f64> = json
            .joints
            .iter()
            .map(|j| rng.range(j.q_min_deg, j.q_max_deg).to_radians())
            .collect();
        let d = (ca.point(&a.values, &q, OutputFrame::Base).1
            - cb.point(&b.values, &q, OutputFrame::Base).1)
            .norm();
        assert!(d < 1e-6, "{d} mm at {q:?}");
    }
    for (j, (x, y)) in robot.joints.iter().zip(&json.joints).enumerate() {
        assert!(
            (x.q_min_deg - y.q_min_deg).abs() < 1e-9 && (x.q_max_deg - y.q_max_deg).abs() < 1e-9,
            "joint {}",
            j + 1
        );
    }
    assert!(robot.links.is_some());
}
