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
