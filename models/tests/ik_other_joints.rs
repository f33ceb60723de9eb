//! Numerical IK restarts draw only the joints that move the end effector: the joints of the
//! other arm of a two-arm robot come back as the seed had them.
#![allow(clippy::unwrap_used)]

use embodied_models::{IkOptions, Rng, builtin};

#[test]
fn restarts_leave_the_other_arm_where_the_seed_has_it() {
    let two = builtin("two-irp6").unwrap();
    // q: the track, the on-track arm's six joints, the postument arm's six.
    let mut rng = Rng::new(11);
    let mut restarted = 0;
    for case in 0..20 {
        let goal = two.random_configuration(&mut rng);
        let (_, target) = two.end_effector_poses(&goal, 1);
        // The on-track arm (and the track) anywhere within their limits and strokes: a restart
        // that drew them again would not land on these values.
        let seed = two.random_configuration(&mut rng);
        let options =
            IkOptions { closed_form: false, max_iterations: 100, restarts: 50, seed: case, ..Default::default() };
        let first_alone = two.inverse_kinematics(1, &target, &seed, &IkOptions { restarts: 0, ..options.clone() });
        let q = two.inverse_kinematics(1, &target, &seed, &options).unwrap();
        if first_alone.is_err() {
            restarted += 1;
        }
        assert_eq!(q[..7], seed[..7], "case {case}: the other arm moved");
        let (_, reached) = two.end_effector_poses(&q, 1);
        assert!((reached.translation.vector - target.translation.vector).norm() < 1e-5, "case {case}");
    }
    // The property is about restarts: most cases must have needed one.
    assert!(restarted >= 10, "only {restarted} of 20 cases restarted");
}

/// The other arm's screws out of their strokes in the seed (the caller's business) do not stop
/// this arm's IK, closed form or numerical: only the screws driving this arm's joints count.
#[test]
fn the_other_arms_strokes_do_not_stop_this_arms_ik() {
    let two = builtin("two-irp6").unwrap();
    assert!(!two.actuators().is_empty(), "test setup: screws");
    let limits = two.limits();
    let mut rng = Rng::new(3);
    // The track and the on-track arm anywhere within their limits, out of some stroke; the
    // postument arm within its strokes (as `random_configuration` drew it).
    let seed = (0..10_000)
        .find_map(|_| {
            let mut q = two.random_configuration(&mut rng);
            for (k, v) in q[..7].iter_mut().enumerate() {
                *v = rng.range(limits[k].lower, limits[k].upper);
            }
            (!two.strokes_hold(&q)).then_some(q)
        })
        .expect("test setup: a seed out of the on-track arm's strokes");
    for case in 0..10 {
        let goal = two.random_configuration(&mut rng);
        let (_, target) = two.end_effector_poses(&goal, 1);
        for closed_form in [true, false] {
            let options = IkOptions { closed_form, seed: case, ..Default::default() };
            let q = two
                .inverse_kinematics(1, &target, &seed, &options)
                .unwrap_or_else(|e| panic!("case {case}, closed form {closed_form}: {e}"));
            assert_eq!(q[..7], seed[..7], "case {case}: the other arm moved");
            let (_, reached) = two.end_effector_poses(&q, 1);
            assert!((reached.translation.vector - target.translation.vector).norm() < 1e-5, "case {case}");
        }
    }
}
