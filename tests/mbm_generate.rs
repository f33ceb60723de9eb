//! `embodied bench mbm-generate`: generated problems read back through `bench mbm`'s loader, with
//! their goals on the query poses and their starts and goals valid; bad flags are clear errors.

use std::path::{Path, PathBuf};
use std::process::Command;

use embodied::mbm::{MbmArgs, find_problems, sample_problems};
use embodied::mbm_generate::{Family, GenerateArgs, GenerateError, Solid, UR5_START, generate_mbm, parse_families};
use embodied_models::nalgebra::Isometry3;
use embodied_planner::moveit::{PlanningScene, load_scene};

fn robot_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("models/tests/fixtures")
}

/// A fresh folder under the system's temporary folder, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("embodied-mbm-generate-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        Self(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn generate_args(families: Vec<Family>, count: usize, seed: u64, out: &Path) -> GenerateArgs {
    GenerateArgs {
        urdf: robot_dir().join("ur5_spherized.urdf"),
        srdf: robot_dir().join("ur5.srdf"),
        families,
        count,
        seed,
        out: out.to_path_buf(),
    }
}

/// The pose of object `id` in a loaded scene (its only primitive).
fn object_pose(scene: &PlanningScene, id: &str) -> Option<Isometry3<f64>> {
    scene.objects.iter().find(|o| o.id == id).and_then(|o| o.primitives.first()).map(|p| p.pose)
}

#[test]
fn generated_problems_load_back_valid_and_on_their_queries() {
    let dir = TempDir::new("all");
    let count = 3;
    let mut progress = Vec::new();
    let outcomes = generate_mbm(&generate_args(Family::ALL.to_vec(), count, 7, &dir.0), &mut |f, done, total| {
        progress.push((f, done, total))
    })
    .expect("generation succeeds");
    assert_eq!(outcomes.len(), 4);
    for o in &outcomes {
        assert_eq!(o.problems, count);
        assert!(o.scenes_sampled >= count && o.ik_calls >= count, "{o:?}");
    }
    assert_eq!(progress.len(), 4 * (count + 1));

    // `bench mbm`'s discovery and loader: every problem is found, and none is dropped as invalid
    // (start or goal in collision or outside the limits).
    let args = MbmArgs::new(robot_dir().join("ur5_spherized.urdf"), robot_dir().join("ur5.srdf"), &dir.0);
    let files = find_problems(&args).expect("problems found");
    assert_eq!(files.len(), 4 * count);
    let loaded = sample_problems(&args, files.len()).expect("problems load");
    assert_eq!(loaded.len(), files.len(), "a generated start or goal is invalid");

    for (file, problem) in files.iter().zip(&loaded) {
        assert_eq!(problem.name, format!("{}/{:04}", file.family, file.index));
        let family = Family::ALL.iter().copied().find(|f| f.folder() == file.family).expect("a known family");
        let spec = family.spec();
        let scene = load_scene(&file.scene).expect("scene loads");

        // The template's objects, with their solids.
        let ids: Vec<&str> = scene.objects.iter().map(|o| o.id.as_str()).collect();
        let template: Vec<&str> = spec.objects.iter().map(|t| t.id).collect();
        assert_eq!(ids, template, "{}", problem.name);
        for (o, t) in scene.objects.iter().zip(spec.objects) {
            assert_eq!(o.primitives.len(), 1);
            let shape = &o.primitives[0].shape;
            match (t.solid, shape) {
                (Solid::Box(size), embodied_models::Shape::Cuboid { half_extents }) => {
                    assert!((0..3).all(|i| (2.0 * half_extents[i] - size[i]).abs() < 1e-12), "{}", t.id);
                }
                (Solid::Cylinder { height, radius }, embodied_models::Shape::Cylinder { radius: r, half_height }) => {
                    assert!((r - radius).abs() < 1e-12 && (2.0 * half_height - height).abs() < 1e-12, "{}", t.id);
                }
                (solid, shape) => panic!("{}: {solid:?} written as {shape:?}", t.id),
            }
        }

        // The goal puts the tool on the goal query of one of its target objects (FK).
        let arm = problem.model.robot();
        let tip = arm.link_index("ee_link").expect("ee_link");
        let on_query = |query: &embodied::mbm_generate::Query, q: &[f64]| {
            let pose = arm.link_pose(q, tip);
            query.objects.iter().any(|id| {
                let object = object_pose(&scene, id).expect("target object in the scene");
                query.accepts(&query.target(&object, spec.ee_offset), &pose, 1e-6)
            })
        };
        assert!(on_query(&spec.goal_query, &problem.goal), "{}: goal off its query", problem.name);
        match &spec.start_query {
            Some(query) => assert!(on_query(query, &problem.start), "{}: start off its query", problem.name),
            None => assert_eq!(problem.start, UR5_START.to_vec(), "{}", problem.name),
        }
        // The goal is not behind the pedestal from the start (the lift's joint limits).
        assert!(!embodied::mbm_generate::lift_passes_pedestal(&problem.model, &problem.start, &problem.goal));
        // Start and goal within the limits and collision-free, as bench mbm checks them.
        for q in [&problem.start, &problem.goal] {
            assert!(arm.within_limits(q), "{}", problem.name);
            assert!(problem.model.first_collision(q).is_none(), "{}", problem.name);
            assert!(!embodied::mbm_generate::touches_pedestal(&problem.model, q), "{}", problem.name);
        }
    }
}

#[test]
fn the_same_seed_gives_the_same_files_and_a_smaller_run_leaves_no_stale_ones() {
    let (a, b) = (TempDir::new("seed-a"), TempDir::new("seed-b"));
    generate_mbm(&generate_args(vec![Family::Cage], 3, 11, &a.0), &mut |_, _, _| {}).expect("first run");
    generate_mbm(&generate_args(vec![Family::Cage], 2, 11, &b.0), &mut |_, _, _| {}).expect("second run");
    for i in 1..=2 {
        for kind in ["scene", "request"] {
            let name = format!("cage_ur5/{kind}{i:04}.yaml");
            let (x, y) = (std::fs::read(a.0.join(&name)), std::fs::read(b.0.join(&name)));
            assert_eq!(x.expect("written"), y.expect("written"), "{name} differs between runs");
        }
    }
    // Over the 3-problem folder, a 2-problem run removes problem 3.
    generate_mbm(&generate_args(vec![Family::Cage], 2, 11, &a.0), &mut |_, _, _| {}).expect("third run");
    assert!(!a.0.join("cage_ur5/scene0003.yaml").exists());
    assert!(!a.0.join("cage_ur5/request0003.yaml").exists());
    assert!(a.0.join("cage_ur5/scene0002.yaml").exists());
}

#[test]
fn bad_arguments_are_clear_errors() {
    assert_eq!(parse_families("all").expect("all"), Family::ALL.to_vec());
    assert_eq!(parse_families("bookshelf_thin").expect("one"), vec![Family::BookshelfThin]);
    let unknown = parse_families("cages").expect_err("unknown family");
    assert!(matches!(unknown, GenerateError::UnknownFamily { .. }));
    assert!(unknown.to_string().contains("cages") && unknown.to_string().contains("table_under_pick"));

    let dir = TempDir::new("bad");
    let zero = generate_mbm(&generate_args(vec![Family::Cage], 0, 1, &dir.0), &mut |_, _, _| {});
    assert!(matches!(zero, Err(GenerateError::ZeroCount)));

    // An output folder below a regular file cannot be made.
    std::fs::create_dir_all(&dir.0).expect("temp folder");
    let file = dir.0.join("a-file");
    std::fs::write(&file, "x").expect("file written");
    let unwritable = generate_mbm(&generate_args(vec![Family::Cage], 1, 1, &file.join("out")), &mut |_, _, _| {});
    let Err(e) = unwritable else { panic!("writing below a file succeeded") };
    assert!(matches!(e, GenerateError::Write { .. }), "{e:?}");
    assert!(e.to_string().contains("cannot write"), "{e}");
}

#[test]
fn the_cli_refuses_bad_flags_without_panicking() {
    let dir = TempDir::new("cli");
    std::fs::create_dir_all(&dir.0).expect("temp folder");
    let file = dir.0.join("a-file");
    std::fs::write(&file, "x").expect("file written");
    let urdf = robot_dir().join("ur5_spherized.urdf");
    let srdf = robot_dir().join("ur5.srdf");
    let out_ok = dir.0.join("out");
    let out_bad = file.join("out");
    let cases: [(&str, &str, &Path, &str); 3] = [
        ("cages", "1", &out_ok, "unknown family `cages`"),
        ("cage", "0", &out_ok, "--count must be at least 1"),
        ("cage", "1", &out_bad, "cannot write"),
    ];
    for (family, count, out, expected) in cases {
        let output = Command::new(env!("CARGO_BIN_EXE_embodied"))
            .args(["bench", "mbm-generate", "--urdf"])
            .arg(&urdf)
            .arg("--srdf")
            .arg(&srdf)
            .args(["--family", family, "--count", count, "--out"])
            .arg(out)
            .output()
            .expect("the binary runs");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{family} {count}: {stderr}");
        assert!(stderr.contains(expected), "{family} {count}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}
