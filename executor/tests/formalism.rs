//! One test per concept of the formalism; each can fail.

use embodied_executor::*;
use embodied_models::JointLimits;

fn limits2() -> Vec<JointLimits> {
    vec![JointLimits::new(-1.0, 1.0, 1.0, 10.0); 2]
}

fn servo2() -> ServoModel {
    ServoModel::new(limits2(), &[0.0, 0.0]).expect("valid servo")
}

/// An effector that executes commands exactly (no dynamics), with generous limits.
struct Ideal {
    limits: Vec<JointLimits>,
    q: Vec<f64>,
    qd: Vec<f64>,
}

impl Ideal {
    fn new(dof: usize) -> Self {
        Self { limits: vec![JointLimits::new(-1e6, 1e6, 1e6, 1e9); dof], q: vec![0.0; dof], qd: vec![0.0; dof] }
    }
}

impl Effector for Ideal {
    fn limits(&self) -> &[JointLimits] {
        &self.limits
    }
    fn q(&self) -> &[f64] {
        &self.q
    }
    fn qd(&self) -> &[f64] {
        &self.qd
    }
    fn execute(&mut self, c: &JointCommand, dt: f64) {
        for i in 0..self.q.len() {
            self.qd[i] = c.qd[i];
            self.q[i] += c.qd[i] * dt;
        }
    }
}

fn velocity(v: f64) -> impl FnMut(&mut (), &InputImages, &mut OutputImages) + Send {
    move |_: &mut (), i: &InputImages, o: &mut OutputImages| o.set_velocity_target(&vec![v; i.dof()])
}

fn run_records(rt: &mut Runtime, steps: u64) -> (Vec<StepRecord>, Result<(), ExecutorError>) {
    let mut out = Vec::new();
    let r = rt.run(steps, |rec| out.push(rec.clone()));
    (out, r)
}

#[test]
fn exactly_one_predicate_violation_is_reported_with_agent_step_and_predicates() {
    let program = Reactive::exactly_one("main")
        .rule(Predicate::new("early", |_: &(), i: &InputImages| i.step() < 5), Primitive::new("a", 1, velocity(0.5)))
        .rule(Predicate::new("late", |_: &(), i: &InputImages| i.step() >= 3), Primitive::new("b", 1, velocity(-0.5)));
    let agent = Agent::new("arm", (), program).with_effector(servo2()).expect("effector");
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(agent);
    let (records, result) = run_records(&mut rt, 100);
    let err = result.expect_err("two predicates held at step 3");
    assert_eq!(
        err,
        ExecutorError::SpecificationError {
            agent: "arm".into(),
            step: 3,
            behaviour: "main".into(),
            held: vec!["early".into(), "late".into()],
        }
    );
    assert!(err.to_string().contains("exactly one predicate must hold, but 2 held: early, late"));
    // Log complete up to the failure, then a safe halt to rest.
    assert_eq!(records[3].step, 3);
    assert!(matches!(records[3].agents[0].events[0], embodied_executor::Event::SpecificationError { .. }));
    assert_eq!(records.last().expect("records").agents[0].behaviour, "safe-halt");
    assert!(rt.is_at_rest());
    assert!(rt.step().is_err(), "a failed run stays stopped");
}

#[test]
fn no_predicate_and_no_main_reaction_is_a_specification_error_not_a_panic() {
    let program = Reactive::priority("main")
        .rule(Predicate::new("never", |_: &(), _: &InputImages| false), Primitive::new("a", 1, velocity(0.5)));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("arm", (), program).with_effector(servo2()).expect("effector"));
    let err = rt.run(10, |_| {}).expect_err("nothing to do");
    assert!(matches!(&err, ExecutorError::SpecificationError { step: 0, held, .. } if held.is_empty()));
    assert!(err.to_string().contains("no predicate holds and there is no main"));
}

#[test]
fn priority_order_is_subsumption_suppression() {
    let program = Reactive::priority("main")
        .rule(
            Predicate::new("obstacle", |_: &(), i: &InputImages| (10..20).contains(&i.step())),
            Primitive::new("avoid", 1, velocity(-0.2)),
        )
        .rule(
            Predicate::new("late", |_: &(), i: &InputImages| i.step() >= 15),
            Primitive::new("sprint", 1, velocity(0.4)),
        )
        // A long behaviour that the reflex must pre-empt.
        .main_reaction(Primitive::new("cruise", 1000, velocity(0.2)));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("arm", (), program).with_effector(Ideal::new(1)).expect("effector"));
    let (records, result) = run_records(&mut rt, 30);
    result.expect("runs");
    let b = |k: usize| records[k].agents[0].behaviour.as_str();
    assert_eq!(b(9), "main/cruise");
    assert_eq!(b(10), "main/avoid");
    assert_eq!(b(16), "main/avoid", "the higher rule suppresses the lower even when both hold");
    assert_eq!(b(20), "main/sprint");
    assert_eq!(records[12].agents[0].qd, vec![-0.2]);
    assert_eq!(records[25].agents[0].qd, vec![0.4]);
}

#[test]
fn nested_behaviour_uses_its_local_predicates() {
    let inner = Reactive::priority("inner")
        .rule(
            Predicate::new("even", |_: &(), i: &InputImages| i.step().is_multiple_of(2)),
            Primitive::new("even-step", 1, velocity(0.1)),
        )
        .main_reaction(Primitive::new("odd-step", 1, velocity(-0.1)));
    let program = Reactive::priority("main")
        .rule(Predicate::new("after-5", |_: &(), i: &InputImages| i.step() >= 5), inner)
        .main_reaction(Primitive::new("start", 1, velocity(0.0)));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("arm", (), program).with_effector(Ideal::new(1)).expect("effector"));
    let (records, _) = run_records(&mut rt, 10);
    assert_eq!(records[4].agents[0].behaviour, "main/start");
    assert_eq!(records[5].agents[0].behaviour, "main/inner/odd-step");
    assert_eq!(records[6].agents[0].behaviour, "main/inner/even-step");
}

#[test]
fn primitive_behaviour_lasts_n_s_steps_then_decision_is_retaken() {
    struct Count(u32);
    let program = Reactive::priority("main").main_reaction(Primitive::new(
        "b",
        4,
        |c: &mut Count, _: &InputImages, _: &mut OutputImages| c.0 += 1,
    ));
    let program = Reactive::priority("main")
        .rule(Predicate::new("step 2", |_: &Count, i: &InputImages| i.step() == 2), program)
        .main_reaction(Primitive::new("idle", 1, |_: &mut Count, _: &InputImages, _: &mut OutputImages| {}));
    // Chosen at step 2, the 4-step behaviour runs steps 2..=5 whatever the predicates say.
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("c", Count(0), program));
    let (records, result) = run_records(&mut rt, 8);
    result.expect("runs");
    let paths: Vec<_> = records.iter().map(|r| r.agents[0].behaviour.as_str()).collect();
    assert_eq!(
        paths,
        [
            "main/idle",
            "main/idle",
            "main/main/b",
            "main/main/b",
            "main/main/b",
            "main/main/b",
            "main/idle",
            "main/idle"
        ]
    );
}

#[test]
fn composers_compute_the_paper_formulas() {
    let cmd = |q: f64, qd: f64| JointCommand { mode: CommandMode::Position, q: vec![q; 2], qd: vec![qd; 2] };
    let parts = [cmd(0.0, 1.0), cmd(1.0, -3.0), cmd(2.0, 2.0)];
    let mut out = cmd(9.0, 9.0);
    let all = [0, 1, 2];
    // Eq. (16): weights 1, 3, 4 -> positions (0*1 + 1*3 + 2*4)/8, velocities (1 - 9 + 8)/8.
    assert!(Composer::WeightedSum(vec![1.0, 3.0, 4.0]).compose(&all, |k| &parts[k], &mut out));
    assert!((out.q[0] - 11.0 / 8.0).abs() < 1e-12 && out.qd[1].abs() < 1e-12);
    // Only active rules count in w.
    assert!(Composer::WeightedSum(vec![1.0, 3.0, 4.0]).compose(&[0, 1], |k| &parts[k], &mut out));
    assert!((out.qd[0] - (1.0 - 9.0) / 4.0).abs() < 1e-12);
    // Eq. (15): largest velocity magnitude.
    assert!(Composer::Max.compose(&all, |k| &parts[k], &mut out));
    assert_eq!(out.qd[0], -3.0);
    // Suppression: the first active rule replaces the others.
    assert!(Composer::Suppress.compose(&[1, 2], |k| &parts[k], &mut out));
    assert_eq!(out.q[0], 1.0);
    // Inhibition: 2 eliminates 0 while active; the survivors (1, 2) are averaged.
    assert!(Composer::Inhibit(vec![(2, 0)]).compose(&all, |k| &parts[k], &mut out));
    assert!((out.qd[0] - (-0.5)).abs() < 1e-12);
    assert!(Composer::Inhibit(vec![(2, 0)]).compose(&[0, 1], |k| &parts[k], &mut out));
    assert!((out.qd[0] - (-1.0)).abs() < 1e-12);
    // Selection function.
    let last = Composer::Select(Box::new(|c: &[usize]| c.last().copied()));
    assert!(last.compose(&all, |k| &parts[k], &mut out));
    assert_eq!(out.q[0], 2.0);
    assert!(!Composer::Max.compose(&[], |k| &parts[k], &mut out));
}

#[test]
fn weighted_composition_reaches_the_effector() {
    let program = Reactive::composed("main", Composer::WeightedSum(vec![1.0, 3.0]))
        .rule(Predicate::always("p1"), Primitive::new("slow", 1, velocity(1.0)))
        .rule(Predicate::always("p2"), Primitive::new("fast", 1, velocity(2.0)));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("arm", (), program).with_effector(Ideal::new(2)).expect("effector"));
    let rec = rt.step().expect("step");
    assert_eq!(rec.agents[0].qd, vec![1.75, 1.75]);
    assert_eq!(rec.agents[0].behaviour, "main/[slow+fast]");
}

#[derive(Default)]
struct MoveLog {
    firsts: u32,
    nexts: u32,
    ended_at: Option<u64>,
}

#[test]
fn move_ends_on_its_terminal_condition_and_wait_on_its_initial_condition() {
    let go = Move::new(
        "go",
        |c: &mut MoveLog, i: &InputImages, o: &mut OutputImages| {
            c.firsts += 1;
            o.set_velocity_target(&vec![0.5; i.dof()]);
        },
        |c: &mut MoveLog, i: &InputImages, o: &mut OutputImages| {
            c.nexts += 1;
            o.set_velocity_target(&vec![0.5; i.dof()]);
        },
        Predicate::new("reached", |_: &MoveLog, i: &InputImages| i.q()[0] >= 0.01),
    );
    let program = Sequence::new("task")
        .then(Wait::new("wait", Predicate::new("start", |_: &MoveLog, i: &InputImages| i.step() >= 50)))
        .then(go)
        .then(Primitive::new("stop", 1000, |c: &mut MoveLog, i: &InputImages, _: &mut OutputImages| {
            c.ended_at.get_or_insert(i.step());
        }));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("arm", MoveLog::default(), program).with_effector(Ideal::new(1)).expect("effector"));
    let (records, result) = run_records(&mut rt, 100);
    result.expect("runs");
    let b = |k: usize| records[k].agents[0].behaviour.as_str();
    assert_eq!(b(49), "task/wait");
    assert_eq!(records[49].agents[0].qd, vec![0.0]);
    assert_eq!(b(50), "task/go", "Wait ends in the step its initial condition holds");
    // 0.5 rad/s at 1 ms: q reaches 0.01 after 20 steps (steps 50..69); the terminal condition,
    // tested on c^i, holds at step 70, where `stop` takes over.
    let first_at = (0..100).find(|&k| b(k) == "task/stop").expect("the Move ended");
    assert_eq!(first_at, 70);
    assert!(records[69].agents[0].q[0] >= 0.01 - 1e-12 && records[68].agents[0].q[0] < 0.01);
}

#[test]
fn parallel_moves_are_composed_before_reaching_the_effector() {
    let short = Move::new(
        "short",
        velocity(1.0),
        velocity(1.0),
        Predicate::new("t>=5", |_: &(), i: &InputImages| i.step() >= 5),
    );
    let long = Move::new(
        "long",
        velocity(3.0),
        velocity(3.0),
        Predicate::new("t>=10", |_: &(), i: &InputImages| i.step() >= 10),
    );
    let program = Reactive::composed("both", Composer::WeightedSum(vec![1.0, 1.0]))
        .rule(Predicate::new("go", |_: &(), i: &InputImages| i.step() == 0), short)
        .rule(Predicate::new("go", |_: &(), i: &InputImages| i.step() == 0), long)
        .main_reaction(Primitive::new("rest", 1, velocity(0.0)));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("arm", (), program).with_effector(Ideal::new(1)).expect("effector"));
    let (records, result) = run_records(&mut rt, 12);
    result.expect("runs");
    assert_eq!(records[0].agents[0].qd, vec![2.0]);
    assert_eq!(records[0].agents[0].behaviour, "both/[short+long]");
    assert_eq!(records[5].agents[0].qd, vec![3.0]);
    assert_eq!(records[5].agents[0].behaviour, "both/[long]");
    assert_eq!(records[10].agents[0].qd, vec![0.0]);
    assert_eq!(records[10].agents[0].behaviour, "both/rest");
}

#[test]
fn transmission_latency_and_loss() {
    #[derive(Default)]
    struct Rx(Vec<(u64, f64)>);
    let run = |latency: u32, loss: f64, seed: u64| {
        let mut rt = Runtime::new(RuntimeConfig { seed, ..RuntimeConfig::default() });
        let a = rt.add_agent(Coordinator::new("a", (), sender_clone(latency)));
        let b = rt.add_agent(Coordinator::new("b", Rx::default(), receiver_clone()));
        rt.connect(a, b, Link { latency, loss }).expect("connect");
        rt.run(1000, |_| {}).expect("runs");
        (rt.channel_stats(a, b).expect("channel"), rt)
    };
    // Closures are not Clone; rebuild the programs per run.
    fn sender_clone(_: u32) -> Reactive<()> {
        Reactive::priority("tx").main_reaction(Primitive::new(
            "send",
            1,
            |_: &mut (), i: &InputImages, o: &mut OutputImages| {
                o.send(AgentId(1), Message::new(7, &[i.step() as f64]));
            },
        ))
    }
    fn receiver_clone() -> Reactive<Rx> {
        Reactive::priority("rx").main_reaction(Primitive::new(
            "listen",
            1,
            |c: &mut Rx, i: &InputImages, _: &mut OutputImages| {
                for m in i.messages() {
                    c.0.push((i.step(), m.message.word(0)));
                }
            },
        ))
    }

    // Latency: a message sent at step i is read at step i + 1 + latency.
    let mut rt = Runtime::new(RuntimeConfig::default());
    let mut got = Vec::new();
    let a = rt.add_agent(Coordinator::new("a", (), sender_clone(0)));
    let b = rt.add_agent(Coordinator::new(
        "b",
        (),
        Reactive::priority("rx").main_reaction(Primitive::new(
            "listen",
            1,
            |_: &mut (), i: &InputImages, o: &mut OutputImages| {
                for m in i.messages() {
                    o.event(format!("{}<-{}", i.step(), m.message.word(0)));
                }
            },
        )),
    ));
    rt.connect(a, b, Link { latency: 3, loss: 0.0 }).expect("connect");
    rt.run(10, |r| got.extend(r.agents[1].events.iter().map(|e| e.to_string()))).expect("runs");
    assert_eq!(got, vec!["4<-0", "5<-1", "6<-2", "7<-3", "8<-4", "9<-5"]);

    let (stats, _) = run(0, 0.3, 11);
    assert_eq!(stats.sent, 1000);
    assert!(stats.sent - stats.lost - stats.delivered <= 1, "at most the last message in flight");
    assert!((230..370).contains(&stats.lost), "lost {} of 1000 at p = 0.3", stats.lost);
    let (again, _) = run(0, 0.3, 11);
    assert_eq!(stats, again, "losses are seeded");
    let (none, _) = run(5, 0.0, 11);
    assert_eq!((none.lost, none.delivered), (0, 994));
}

#[test]
fn sending_without_a_channel_stops_the_run() {
    let tx = Reactive::priority("tx").main_reaction(Primitive::new(
        "send",
        1,
        |_: &mut (), _: &InputImages, o: &mut OutputImages| {
            o.send(AgentId(0), Message::new(1, &[]));
        },
    ));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Coordinator::new("lonely", (), tx));
    let err = rt.run(3, |_| {}).expect_err("no channel");
    assert!(matches!(err, ExecutorError::NoChannel { step: 0, to: 0, .. }));
}

#[test]
fn sensor_configuration_changes_rate_and_region_of_interest() {
    // Sensor 0 = NearestObstacle. Obstacle A is in the initial region; B appears at step 20.
    #[derive(Default)]
    struct Seen(Vec<(u64, bool, usize)>);
    let program = Reactive::priority("main").main_reaction(Primitive::new(
        "look",
        1,
        |c: &mut Seen, i: &InputImages, o: &mut OutputImages| {
            let r = i.sensor(0);
            c.0.push((i.step(), r.fresh, r.len));
            if r.fresh && r.len > 0 {
                o.event(format!("{}:{}", i.step(), r.values[4]));
            }
            if i.step() == 30 {
                o.configure_sensor(
                    0,
                    SensorConfig { period: 1, region: Region { center: [5.0, 0.0, 0.0], radius: 1.0 }, threshold: 0.0 },
                );
            }
        },
    ));
    let camera = ReceptorSpec { detector_range: Some(f64::INFINITY), ..ReceptorSpec::default() };
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.world_mut().add_obstacle(Obstacle::fixed("a", [1.0, 0.0, 0.0], 0.1));
    rt.world_mut().add_obstacle(Obstacle { appears_at: 20, ..Obstacle::fixed("b", [5.0, 0.0, 0.0], 0.1) });
    rt.add_agent(
        Coordinator::new("eye", Seen::default(), program)
            .with_sensor(NearestObstacle, SensorConfig { period: 10, ..SensorConfig::default() })
            .with_receptors(camera),
    );
    let mut events = Vec::new();
    rt.run(35, |r| events.extend(r.agents[0].events.iter().map(|e| e.to_string()))).expect("runs");
    // Period 10: readings at steps 0, 10, 20, 30 (obstacle a is nearest); reconfigured at 30, the
    // region now holds only b, read every step from 31 on.
    assert_eq!(events, vec!["0:0", "10:0", "20:0", "30:0", "31:1", "32:1", "33:1", "34:1"]);
}

#[test]
fn coordinator_commands_two_agents_in_a_hierarchy() {
    const GOTO: u32 = 1;
    const ARRIVED: u32 = 2;
    const START: u32 = 3;
    #[derive(Default)]
    struct Arm {
        target: Option<f64>,
    }
    let arm_program = || {
        Reactive::priority("arm")
            .rule(
                Predicate::new("order", |_: &Arm, i: &InputImages| {
                    i.messages().iter().any(|m| m.message.tag() == Some(GOTO))
                }),
                Primitive::new("accept", 1, |c: &mut Arm, i: &InputImages, _: &mut OutputImages| {
                    c.target =
                        i.messages().iter().rev().find(|m| m.message.tag() == Some(GOTO)).map(|m| m.message.word(0));
                }),
            )
            .rule(
                Predicate::new("arrived", |c: &Arm, i: &InputImages| {
                    c.target.is_some_and(|t| (i.q()[0] - t).abs() < 1e-3 && i.qd()[0].abs() < 1e-3)
                }),
                Primitive::new("report", 1, |c: &mut Arm, i: &InputImages, o: &mut OutputImages| {
                    o.send(AgentId(1), Message::new(ARRIVED, &[i.agent().0 as f64]));
                    c.target = None;
                }),
            )
            .rule(
                Predicate::new("busy", |c: &Arm, _: &InputImages| c.target.is_some()),
                Primitive::new("track", 1, |c: &mut Arm, i: &InputImages, o: &mut OutputImages| {
                    let mut q = i.q().to_vec();
                    q[0] = c.target.unwrap_or(q[0]);
                    o.set_position_target(&q, &[0.0, 0.0]);
                }),
            )
            .main_reaction(Wait::new("idle", Predicate::new("never", |_: &Arm, _: &InputImages| false)))
    };
    // The cell coordinator: on START, send both arms to 0.3, then both to -0.2, then done.
    #[derive(Default)]
    struct Cell {
        phase: u32,
        arrivals: u32,
    }
    let targets = [0.3, -0.2];
    let cell = Reactive::priority("cell").main_reaction(Primitive::new(
        "sequence",
        1,
        move |c: &mut Cell, i: &InputImages, o: &mut OutputImages| {
            if i.messages().iter().any(|m| m.message.tag() == Some(START)) && c.phase == 0 {
                c.phase = 1;
                for arm in [2, 3] {
                    o.send(AgentId(arm), Message::new(GOTO, &[targets[0]]));
                }
            }
            c.arrivals += i.messages().iter().filter(|m| m.message.tag() == Some(ARRIVED)).count() as u32;
            if c.arrivals == 2 && (1..=2).contains(&c.phase) {
                c.arrivals = 0;
                c.phase += 1;
                o.event(format!("phase {}", c.phase));
                if c.phase == 2 {
                    for arm in [2, 3] {
                        o.send(AgentId(arm), Message::new(GOTO, &[targets[1]]));
                    }
                }
            }
        },
    ));
    // The top of the hierarchy starts the cell coordinator at step 10.
    let top = Reactive::priority("top")
        .rule(
            Predicate::new("t=10", |_: &(), i: &InputImages| i.step() == 10),
            Primitive::new("start", 1, |_: &mut (), _: &InputImages, o: &mut OutputImages| {
                o.send(AgentId(1), Message::new(START, &[]));
            }),
        )
        .main_reaction(Primitive::new("idle", 1, |_: &mut (), _: &InputImages, _: &mut OutputImages| {}));
    let mut rt = Runtime::new(RuntimeConfig::default());
    let top = rt.add_agent(Coordinator::new("top", (), top));
    let cell = rt.add_agent(Coordinator::new("cell", Cell::default(), cell));
    let mut arms = Vec::new();
    for name in ["left", "right"] {
        let servo = ServoModel::new(limits2(), &[0.0, 0.0]).expect("servo");
        arms.push(
            rt.add_agent(Agent::new(name, Arm::default(), arm_program()).with_effector(servo).expect("effector")),
        );
    }
    rt.connect(top, cell, Link::IDEAL).expect("link");
    for &arm in &arms {
        rt.connect_both(cell, arm, Link { latency: 2, loss: 0.0 }).expect("link");
    }
    let mut events = Vec::new();
    let mut last = StepRecord::default();
    rt.run(3000, |r| {
        events.extend(r.agents[1].events.iter().map(|e| e.to_string()));
        last = r.clone();
    })
    .expect("runs");
    assert_eq!(events, vec!["phase 2", "phase 3"]);
    for a in &last.agents[2..] {
        assert!((a.q[0] + 0.2).abs() < 1e-3, "{} ended at {:?}", a.agent, a.q);
        assert_eq!(a.q.len(), 2);
    }
    assert!(last.agents[0].q.is_empty(), "coordinators have no effector");
}

#[test]
fn safe_halt_stops_on_the_path_within_acceleration_limits() {
    let limits = vec![JointLimits::new(-10.0, 10.0, 2.0, 4.0), JointLimits::new(-10.0, 10.0, 2.0, 1.0)];
    let mut servo = SafetyLimiter::new(ServoModel::new(limits.clone(), &[0.0, 0.0]).expect("servo"));
    let dt = 0.001;
    let run_up = JointCommand { mode: CommandMode::Velocity, q: vec![0.0; 2], qd: vec![1.0, 0.5] };
    for _ in 0..2000 {
        servo.execute(&run_up, dt);
    }
    assert_eq!(servo.qd(), &[1.0, 0.5]);
    let mut cmd = JointCommand::hold(&[0.0, 0.0]);
    let mut prev = servo.qd().to_vec();
    let mut steps = 0;
    while servo.qd().iter().any(|v| *v != 0.0) {
        SafeHalt::command_into(servo.q(), servo.qd(), servo.limits(), dt, &mut cmd);
        servo.execute(&cmd, dt);
        let v = servo.qd();
        for i in 0..2 {
            assert!((v[i] - prev[i]).abs() <= limits[i].max_acceleration * dt + 1e-12);
            assert!(v[i] >= 0.0);
        }
        // Same path: velocity direction preserved.
        if v[0] > 1e-9 {
            assert!((v[1] / v[0] - 0.5).abs() < 1e-9);
        }
        prev = v.to_vec();
        steps += 1;
        assert!(steps < 10_000);
    }
    // Joint 1 (0.5 rad/s at 1 rad/s^2) needs 0.5 s; joint 0 is slowed to match.
    assert!((495..=505).contains(&steps), "{steps} steps");
}

#[test]
fn runs_are_deterministic_and_independent_of_threads() {
    let robot = std::sync::Arc::new(embodied_models::builtin("irp6-postument").expect("robot"));
    let build = |parallelism: Parallelism, tasks_per_thread: usize| {
        let mut rt =
            Runtime::new(RuntimeConfig { seed: 42, parallelism, tasks_per_thread, ..RuntimeConfig::default() });
        rt.world_mut()
            .add_obstacle(Obstacle { velocity: [0.0, 0.1, 0.0], ..Obstacle::fixed("ball", [0.8, 0.0, 1.2], 0.2) });
        for k in 0..6 {
            let program = Reactive::priority("main")
                .rule(
                    Predicate::new("near", |_: &(), i: &InputImages| {
                        i.sensor(1).len > 0 && i.sensor(1).values[0] < 0.3
                    }),
                    Primitive::new("avoid", 5, |_: &mut (), i: &InputImages, o: &mut OutputImages| {
                        o.event("avoid");
                        o.set_velocity_target(&vec![-0.2; i.dof()]);
                    }),
                )
                .main_reaction(Primitive::new(
                    "wander",
                    1,
                    move |_: &mut (), i: &InputImages, o: &mut OutputImages| {
                        let mut q = i.sensor(0).as_slice().to_vec();
                        q.resize(i.dof(), 0.0);
                        q[0] += 0.5 * ((i.step() as f64) * 0.003 + k as f64).sin();
                        o.set_position_target(&q, &vec![0.0; i.dof()]);
                        if i.step().is_multiple_of(50) {
                            o.send(AgentId((k + 1) % 6), Message::new(1, &[i.q()[0]]));
                        }
                    },
                ));
            let agent = Agent::embodied(format!("arm{k}"), robot.clone(), None, (), program)
                .expect("agent")
                .with_sensor(JointState, SensorConfig::default())
                .with_sensor(NearestObstacle, SensorConfig { period: 5, ..SensorConfig::default() })
                .with_receptors(ReceptorSpec {
                    encoder_noise: 1e-4,
                    force_stiffness: Some(1e3),
                    force_noise: 0.1,
                    detector_range: Some(1.0),
                    detector_noise: 0.01,
                });
            rt.add_agent(agent);
        }
        for k in 0..6 {
            rt.connect(AgentId(k), AgentId((k + 1) % 6), Link { latency: 1, loss: 0.2 }).expect("link");
        }
        rt
    };
    let log = |parallelism, tasks_per_thread| {
        let mut rt = build(parallelism, tasks_per_thread);
        let mut bytes = Vec::new();
        rt.run(400, |r| {
            serde_json::to_writer(&mut bytes, r).expect("serialise");
            bytes.push(b'\n');
        })
        .expect("runs");
        bytes
    };
    let a = log(Parallelism::Sequential, 1);
    let b = log(Parallelism::Sequential, 1);
    let c = log(Parallelism::Rayon { min_agents: 2 }, 1);
    let d = log(Parallelism::Rayon { min_agents: 2 }, 3);
    assert!(a.len() > 10_000);
    assert_eq!(a, b, "same seed, same bytes");
    assert_eq!(a, c, "threads do not change the log");
    assert_eq!(a, d, "nor does the number of parallel tasks");
    let text = String::from_utf8(a).expect("utf-8");
    assert!(text.contains("\"avoid\""), "the moving obstacle triggered the reflex somewhere");
}

#[test]
fn writing_the_wrong_number_of_joints_is_reported() {
    let program = Reactive::priority("main").main_reaction(Primitive::new(
        "bad",
        1,
        |_: &mut (), _: &InputImages, o: &mut OutputImages| {
            o.set_velocity_target(&[1.0]);
        },
    ));
    let mut rt = Runtime::new(RuntimeConfig::default());
    rt.add_agent(Agent::new("arm", (), program).with_effector(servo2()).expect("effector"));
    let err = rt.run(5, |_| {}).expect_err("dimension");
    assert!(matches!(err, ExecutorError::DimensionMismatch { expected: 2, got: 1, .. }), "{err}");
}
