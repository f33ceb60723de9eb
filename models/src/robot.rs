//! The kinematic tree: links, joints, end effectors, forward kinematics and Jacobians.

use std::collections::HashSet;

use nalgebra::{DVector, Isometry3, Matrix6xX, Point3, Vector3};

use crate::actuator::ScrewTriangle;
use crate::error::ModelError;
use crate::geometry::PlacedShape;
use crate::joint::{Joint, JointKind, JointLimits};

/// An analytic inverse-kinematics solution a robot's builder attaches to an end effector
/// ([`crate::RobotBuilder::closed_form_ik`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum ClosedForm {
    /// The IRp-6 arm (shared/robots/README.md 1.3.1): the six revolute joints ending at the
    /// flange, built from the standard DH table; up to eight solutions per pose.
    Irp6,
}

/// A closed form resolved against a built robot: which degrees of freedom it solves and where
/// its chain starts.
#[derive(Debug, Clone)]
pub(crate) struct ArmChain {
    pub kind: ClosedForm,
    /// `q` indices of the six arm joints, shoulder first.
    pub dofs: [usize; 6],
    /// The link the first arm joint hangs from, and that joint's origin in it (DH frame 0).
    pub shoulder_link: usize,
    pub shoulder: Isometry3<f64>,
    /// Whether the six joints are every degree of freedom that moves the end effector (no track).
    pub whole: bool,
}

/// A rigid body of the tree with its collision shapes (in the link frame).
#[derive(Debug, Clone)]
pub struct Link {
    /// The link's name.
    pub name: String,
    /// The joint whose child this link is; `None` for the root.
    pub parent_joint: Option<usize>,
    /// Collision shapes, placed in the link frame.
    pub shapes: Vec<PlacedShape>,
}

/// An end effector: a flange frame (a link frame) and a tool frame fixed to it.
#[derive(Debug, Clone)]
pub struct EndEffector {
    /// The end effector's name.
    pub name: String,
    /// The link whose frame is the flange.
    pub link: usize,
    /// Tool frame relative to the flange.
    pub tool: Isometry3<f64>,
}

/// The most degrees of freedom [`Robot::branch_dofs`] are searched for.
const BRANCH_SEARCH_DOFS: usize = 128;

/// A robot: a kinematic tree of joints (revolute, continuous, prismatic, fixed) with limits,
/// collision shapes per link and a self-collision pair filter.
///
/// Links are stored so that a parent always precedes its children; the configuration vector
/// `q` holds one value per degree of freedom, in [`Robot::dof_joints`] order.
#[derive(Debug, Clone)]
pub struct Robot {
    name: String,
    provenance: String,
    links: Vec<Link>,
    joints: Vec<Joint>,
    dof_joints: Vec<usize>,
    end_effectors: Vec<EndEffector>,
    home: Vec<f64>,
    disabled_pairs: HashSet<(usize, usize)>,
    base: Isometry3<f64>,
    /// Per end effector: its closed-form inverse kinematics, if the builder attached one.
    pub(crate) closed_forms: Vec<Option<ArmChain>>,
    /// Linear actuators driving joints through triangles (serial-parallel actuation).
    actuators: Vec<ScrewTriangle>,
    /// [`Robot::independent_dof_groups`], worked out whenever the tree or the actuators change.
    dof_groups: Vec<Vec<usize>>,
    /// [`Robot::branch_dofs`], worked out with `dof_groups`.
    branch_dofs: Vec<usize>,
}

/// Builds a [`Robot`] link by link; [`RobotBuilder::build`] checks and orders the tree.
#[derive(Debug, Clone)]
pub struct RobotBuilder {
    name: String,
    provenance: String,
    links: Vec<Link>,
    joints: Vec<Joint>,
    end_effectors: Vec<(String, String, Isometry3<f64>)>,
    home: Option<Vec<f64>>,
    disabled: Vec<(String, String)>,
    pending_mimic: Vec<(usize, String, f64, f64)>,
    base: Isometry3<f64>,
    closed_forms: Vec<(String, ClosedForm)>,
    actuators: Vec<ScrewTriangle>,
}

impl RobotBuilder {
    /// An empty builder for a robot named `name`.
    pub fn new(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            provenance: String::new(),
            links: Vec::new(),
            joints: Vec::new(),
            end_effectors: Vec::new(),
            home: None,
            disabled: Vec::new(),
            pending_mimic: Vec::new(),
            base: Isometry3::identity(),
            closed_forms: Vec::new(),
            actuators: Vec::new(),
        }
    }
    /// Where the numbers come from (shown in `--help` and `embodied model`).
    pub fn provenance(mut self, text: impl Into<String>) -> Self {
        self.provenance = text.into();
        self
    }
    /// Placement of the root link in the world.
    pub fn base(mut self, base: Isometry3<f64>) -> Self {
        self.base = base;
        self
    }
    /// Add a link; returns its index (before reordering).
    pub fn link(&mut self, name: impl Into<String>, shapes: Vec<PlacedShape>) -> usize {
        self.links.push(Link { name: name.into(), parent_joint: None, shapes });
        self.links.len() - 1
    }
    /// Index of a link by name.
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }
    /// Attach more shapes to a link.
    pub fn add_shapes(&mut self, link: usize, shapes: impl IntoIterator<Item = PlacedShape>) {
        self.links[link].shapes.extend(shapes);
    }
    /// Add a joint between two existing links (indices from [`RobotBuilder::link`]).
    #[allow(clippy::too_many_arguments)]
    pub fn joint(
        &mut self,
        name: impl Into<String>,
        kind: JointKind,
        parent: usize,
        child: usize,
        origin: Isometry3<f64>,
        axis: Vector3<f64>,
        offset: f64,
        post: Isometry3<f64>,
        limits: JointLimits,
    ) -> usize {
        let axis = nalgebra::Unit::try_new(axis, 1e-12).unwrap_or(Vector3::z_axis());
        self.joints.push(Joint {
            name: name.into(),
            kind,
            parent_link: parent,
            child_link: child,
            origin,
            axis,
            offset,
            post,
            limits,
            dof_index: None,
            mimic: None,
        });
        self.joints.len() - 1
    }
    /// Make a joint follow another (by joint name): value = multiplier * q(other) + offset.
    pub fn mimic(&mut self, joint: usize, other: String, multiplier: f64, offset: f64) {
        self.pending_mimic.push((joint, other, multiplier, offset));
    }
    /// Declare an end effector: flange = the named link's frame; tool relative to it.
    pub fn end_effector(&mut self, name: impl Into<String>, link: impl Into<String>, tool: Isometry3<f64>) {
        self.end_effectors.push((name.into(), link.into(), tool));
    }
    /// Attach a closed-form inverse kinematics to the named end effector. [`RobotBuilder::build`]
    /// checks that the chain ending at its flange has the joints the closed form needs.
    pub fn closed_form_ik(&mut self, end_effector: impl Into<String>, kind: ClosedForm) {
        self.closed_forms.push((end_effector.into(), kind));
    }
    /// Drive degrees of freedom by a linear actuator through a triangle: its stroke and speed
    /// limit hold besides the joints' limits.
    pub fn actuator(&mut self, actuator: ScrewTriangle) {
        self.actuators.push(actuator);
    }
    /// The configuration reported as "home" (default: zeros clamped into limits).
    pub fn home(&mut self, q: Vec<f64>) {
        self.home = Some(q);
    }
    /// A link pair never to be checked for self-collision (SRDF `<disable_collisions>`).
    pub fn disable_collisions(&mut self, a: impl Into<String>, b: impl Into<String>) {
        self.disabled.push((a.into(), b.into()));
    }

    /// Check the tree, order links parent-first, number the degrees of freedom.
    pub fn build(self) -> Result<Robot, ModelError> {
        let invalid = |message: String| ModelError::Invalid { robot: self.name.clone(), message };
        let n = self.links.len();
        if n == 0 {
            return Err(invalid("it has no links".into()));
        }
        for (i, l) in self.links.iter().enumerate() {
            if self.links[..i].iter().any(|o| o.name == l.name) {
                return Err(invalid(format!("two links are named `{}`", l.name)));
            }
        }
        for (i, j) in self.joints.iter().enumerate() {
            if self.joints[..i].iter().any(|o| o.name == j.name) {
                return Err(invalid(format!("two joints are named `{}`", j.name)));
            }
        }
        let mut parent_of: Vec<Option<usize>> = vec![None; n];
        for (ji, j) in self.joints.iter().enumerate() {
            if j.parent_link >= n || j.child_link >= n {
                return Err(invalid(format!("joint `{}` refers to a missing link", j.name)));
            }
            if parent_of[j.child_link].is_some() {
                return Err(invalid(format!("link `{}` is the child of two joints", self.links[j.child_link].name)));
            }
            parent_of[j.child_link] = Some(ji);
        }
        let roots: Vec<usize> = (0..n).filter(|&l| parent_of[l].is_none()).collect();
        if roots.len() != 1 {
            let names: Vec<&str> = roots.iter().map(|&l| self.links[l].name.as_str()).collect();
            return Err(invalid(format!("it must have exactly one root link, found {}: {:?}", roots.len(), names)));
        }
        // Depth-first preorder from the root, children in declaration order: parents come
        // before children and each branch stays contiguous.
        let mut order = Vec::with_capacity(n);
        let mut stack = vec![roots[0]];
        while let Some(l) = stack.pop() {
            if order.len() > n {
                break;
            }
            order.push(l);
            let children: Vec<usize> =
                self.joints.iter().filter(|j| j.parent_link == l).map(|j| j.child_link).collect();
            stack.extend(children.into_iter().rev());
        }
        if order.len() != n {
            return Err(invalid("its joints form a cycle or leave links unconnected".into()));
        }
        let mut new_index = vec![0usize; n];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        let mut links: Vec<Link> = order.iter().map(|&old| self.links[old].clone()).collect();
        // Joints in the order of their child links, so joint k moves link k+1.
        let mut joints: Vec<Joint> = order[1..]
            .iter()
            .map(|&child| {
                let Some(ji) = parent_of[child] else { unreachable!("non-root link has a parent") };
                let mut j = self.joints[ji].clone();
                j.parent_link = new_index[j.parent_link];
                j.child_link = new_index[j.child_link];
                j
            })
            .collect();
        for (ji, j) in joints.iter().enumerate() {
            links[j.child_link].parent_joint = Some(ji);
        }
        // Degrees of freedom: every moving joint that does not mimic another.
        let mimics: Vec<(String, String, f64, f64)> = self
            .pending_mimic
            .iter()
            .map(|(j, other, m, o)| (self.joints[*j].name.clone(), other.clone(), *m, *o))
            .collect();
        // Degrees of freedom: every moving joint that does not mimic another, numbered in the
        // order the joints were declared (URDF file order; on-track arm first in two-irp6).
        let mut declared: Vec<usize> = (0..joints.len()).collect();
        declared.sort_by_key(|&ji| self.joints.iter().position(|o| o.name == joints[ji].name));
        let mut dof_joints = Vec::new();
        for ji in declared {
            let j = &mut joints[ji];
            let is_mimic = mimics.iter().any(|(name, ..)| *name == j.name);
            if j.kind != JointKind::Fixed && !is_mimic {
                j.dof_index = Some(dof_joints.len());
                dof_joints.push(ji);
            }
        }
        for (name, other, mult, off) in &mimics {
            let Some(dof) = joints.iter().find(|j| &j.name == other).and_then(|j| j.dof_index) else {
                return Err(invalid(format!("joint `{name}` mimics `{other}`, which is not a degree of freedom")));
            };
            if let Some(j) = joints.iter_mut().find(|j| &j.name == name) {
                j.mimic = Some((dof, *mult, *off));
            }
        }
        let find_link = |name: &str| -> Result<usize, ModelError> {
            links.iter().position(|l| l.name == name).ok_or_else(|| ModelError::NoSuchName {
                robot: self.name.clone(),
                what: "link",
                name: name.to_string(),
            })
        };
        let mut end_effectors = Vec::new();
        for (name, link, tool) in &self.end_effectors {
            end_effectors.push(EndEffector { name: name.clone(), link: find_link(link)?, tool: *tool });
        }
        let mut disabled_pairs = HashSet::new();
        for (a, b) in &self.disabled {
            // Unknown names in an SRDF are common (other groups' links); skip them silently.
            if let (Ok(a), Ok(b)) = (find_link(a), find_link(b)) {
                disabled_pairs.insert((a.min(b), a.max(b)));
            }
        }
        let dof = dof_joints.len();
        let home = match self.home {
            Some(h) if h.len() == dof => h,
            Some(h) => {
                return Err(invalid(format!("home configuration has {} values for {dof} joints", h.len())));
            }
            None => dof_joints.iter().map(|&ji| joints[ji].limits.clamp(0.0)).collect(),
        };
        let mut closed_forms = vec![None; end_effectors.len()];
        for (name, kind) in &self.closed_forms {
            let Some(ee) = end_effectors.iter().position(|e| &e.name == name) else {
                return Err(ModelError::NoSuchName {
                    robot: self.name.clone(),
                    what: "end effector",
                    name: name.clone(),
                });
            };
            closed_forms[ee] = Some(arm_chain(&links, &joints, end_effectors[ee].link, *kind).map_err(&invalid)?);
        }
        let mut robot = Robot {
            closed_forms,
            name: self.name,
            provenance: self.provenance,
            links,
            joints,
            dof_joints,
            end_effectors,
            home,
            disabled_pairs,
            base: self.base,
            actuators: self.actuators,
            dof_groups: Vec::new(),
            branch_dofs: Vec::new(),
        };
        (robot.dof_groups, robot.branch_dofs) = robot.group_dofs();
        Ok(robot)
    }
}

/// Resolve a closed form against the built tree: the six revolute joints nearest the flange link,
/// consecutive, with nothing between the last and the flange.
fn arm_chain(links: &[Link], joints: &[Joint], flange: usize, kind: ClosedForm) -> Result<ArmChain, String> {
    let mut moving = Vec::new();
    let mut l = flange;
    while let Some(ji) = links[l].parent_joint {
        if joints[ji].kind != JointKind::Fixed {
            moving.push(ji);
        }
        l = joints[ji].parent_link;
    }
    let name = &links[flange].name;
    if moving.len() < 6 {
        return Err(format!("the closed form {kind:?} needs six joints up to `{name}`, found {}", moving.len()));
    }
    let arm = &moving[..6];
    // Consecutive: each arm joint's parent link is the child of the next one up the chain.
    let consecutive = joints[arm[0]].child_link == flange
        && arm.windows(2).all(|w| joints[w[0]].parent_link == joints[w[1]].child_link);
    let mut dofs = [0usize; 6];
    for (k, &ji) in arm.iter().rev().enumerate() {
        let j = &joints[ji];
        match (j.kind, j.dof_index, j.mimic) {
            (JointKind::Revolute | JointKind::Continuous, Some(d), None) if consecutive => dofs[k] = d,
            _ => {
                return Err(format!(
                    "the closed form {kind:?} needs six consecutive revolute joints ending at `{name}`; `{}` is not one",
                    j.name
                ));
            }
        }
    }
    let first = &joints[arm[5]];
    Ok(ArmChain { kind, dofs, shoulder_link: first.parent_link, shoulder: first.origin, whole: moving.len() == 6 })
}

impl Robot {
    /// The robot's name.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Where the robot's numbers come from, and what is assumed.
    pub fn provenance(&self) -> &str {
        &self.provenance
    }
    /// Number of degrees of freedom (length of `q`).
    pub fn dof(&self) -> usize {
        self.dof_joints.len()
    }
    /// The links, parents before children.
    pub fn links(&self) -> &[Link] {
        &self.links
    }
    /// The joints, in the order of their child links (joint `k` moves link `k + 1`).
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }
    /// Joint indices of the degrees of freedom, in `q` order.
    pub fn dof_joints(&self) -> &[usize] {
        &self.dof_joints
    }
    /// The joint of degree of freedom `i`.
    pub fn dof_joint(&self, i: usize) -> &Joint {
        &self.joints[self.dof_joints[i]]
    }
    /// Names of the degrees of freedom, in `q` order.
    pub fn joint_names(&self) -> Vec<String> {
        self.dof_joints.iter().map(|&j| self.joints[j].name.clone()).collect()
    }
    /// Limits of the degrees of freedom, in `q` order.
    pub fn limits(&self) -> Vec<JointLimits> {
        self.dof_joints.iter().map(|&j| self.joints[j].limits).collect()
    }
    /// Whether degree of freedom `i` is an unlimited angle (wraps).
    pub fn is_continuous(&self, i: usize) -> bool {
        self.joints[self.dof_joints[i]].kind == JointKind::Continuous
    }
    /// The end effectors.
    pub fn end_effectors(&self) -> &[EndEffector] {
        &self.end_effectors
    }
    /// This robot with one more end effector, `name`, whose flange is link `link` and whose tool
    /// frame is `tool` in it (no closed-form inverse kinematics); returns it and the end effector's
    /// index. Errors: no such link.
    pub fn with_end_effector(
        &self,
        name: &str,
        link: &str,
        tool: Isometry3<f64>,
    ) -> Result<(Robot, usize), ModelError> {
        let Some(link) = self.link_index(link) else {
            return Err(ModelError::NoSuchName { robot: self.name.clone(), what: "link", name: link.to_string() });
        };
        let mut robot = self.clone();
        robot.end_effectors.push(EndEffector { name: name.to_string(), link, tool });
        robot.closed_forms.push(None);
        let index = robot.end_effectors.len() - 1;
        Ok((robot, index))
    }
    /// The home configuration `q` (default: zeros clamped into the limits).
    pub fn home(&self) -> &[f64] {
        &self.home
    }
    /// Placement of the root link in the world.
    pub fn base(&self) -> &Isometry3<f64> {
        &self.base
    }
    /// Move the whole robot (placement of its root in the world).
    pub fn set_base(&mut self, base: Isometry3<f64>) {
        self.base = base;
    }
    /// Index of the link named `name`.
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }
    /// Index of the joint named `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }
    /// Self-collision pairs disabled by the model or its SRDF (indices ordered low, high).
    pub fn disabled_pairs(&self) -> &HashSet<(usize, usize)> {
        &self.disabled_pairs
    }
    /// Add collision shapes (in the link frame) to a link, e.g. an object the link holds.
    /// Out-of-range link indices are ignored.
    pub fn attach_shapes(&mut self, link: usize, shapes: impl IntoIterator<Item = PlacedShape>) {
        if let Some(l) = self.links.get_mut(link) {
            l.shapes.extend(shapes);
        }
    }

    /// A copy with every self-collision pair disabled: the robot against its environment only.
    pub fn without_self_collisions(&self) -> Robot {
        let mut out = self.clone();
        let n = self.links.len();
        for a in 0..n {
            for b in a + 1..n {
                out.disabled_pairs.insert((a, b));
            }
        }
        out
    }

    /// Replace the limits of joint `ji` (by joint index), e.g. with MoveIt's
    /// `joint_limits.yaml`; the home configuration is clamped into the new position limits.
    pub fn set_joint_limits(&mut self, ji: usize, limits: JointLimits) {
        self.joints[ji].limits = limits;
        if let Some(d) = self.joints[ji].dof_index {
            self.home[d] = limits.clamp(self.home[d]);
        }
    }

    /// Replace the provenance text (what the model was made from and what was assumed).
    pub fn set_provenance(&mut self, text: impl Into<String>) {
        self.provenance = text.into();
    }

    /// Disable self-collision checks between two links (by index).
    pub fn disable_pair(&mut self, a: usize, b: usize) {
        self.disabled_pairs.insert((a.min(b), a.max(b)));
    }

    /// Check a configuration's length, finiteness and position limits.
    pub fn check_configuration(&self, q: &[f64]) -> Result<(), ModelError> {
        if q.len() != self.dof() {
            return Err(ModelError::WrongDof { robot: self.name.clone(), expected: self.dof(), got: q.len() });
        }
        for (i, &v) in q.iter().enumerate() {
            let j = self.dof_joint(i);
            if !v.is_finite() {
                return Err(ModelError::NotFinite { joint: j.name.clone(), value: v });
            }
            let l = j.limits;
            if v < l.lower - 1e-9 || v > l.upper + 1e-9 {
                return Err(ModelError::OutOfLimits {
                    joint: j.name.clone(),
                    value: v,
                    lower: l.lower,
                    upper: l.upper,
                });
            }
        }
        for a in &self.actuators {
            if a.stroke_excess(q) > 1e-9 {
                return Err(ModelError::OutOfStroke {
                    actuator: a.name.clone(),
                    length: a.length(q),
                    min: a.min_length,
                    max: a.max_length,
                });
            }
        }
        Ok(())
    }

    /// Whether `q` is within every position limit and every actuator's stroke (no allocation;
    /// for hot paths).
    pub fn within_limits(&self, q: &[f64]) -> bool {
        q.len() == self.dof()
            && q.iter().zip(&self.dof_joints).all(|(&v, &j)| {
                let l = &self.joints[j].limits;
                v.is_finite() && v >= l.lower - 1e-9 && v <= l.upper + 1e-9
            })
            && self.actuators.iter().all(|a| a.stroke_excess(q) <= 1e-9)
    }

    /// Whether every actuator's stroke holds at `q` exactly (no tolerance: the test a sampler
    /// redraws on; true for a robot without actuators).
    pub fn strokes_hold(&self, q: &[f64]) -> bool {
        self.actuators.iter().all(|a| a.stroke_excess(q) <= 0.0)
    }

    /// The linear actuators that drive joints through triangles (empty for a robot whose
    /// joints are driven directly).
    pub fn actuators(&self) -> &[ScrewTriangle] {
        &self.actuators
    }

    /// Add an actuator to a built robot (its degrees of freedom must exist).
    pub fn add_actuator(&mut self, actuator: ScrewTriangle) -> Result<(), ModelError> {
        if let Some(&(k, _)) = actuator.angle.iter().find(|(k, _)| *k >= self.dof()) {
            return Err(ModelError::Invalid {
                robot: self.name.clone(),
                message: format!("actuator `{}` drives degree of freedom {k} of {}", actuator.name, self.dof()),
            });
        }
        self.actuators.push(actuator);
        (self.dof_groups, self.branch_dofs) = self.group_dofs();
        Ok(())
    }

    /// The largest `|dl/dt| / max_speed` over the actuators at `(q, qd)` (0 without actuators).
    pub fn actuator_speed_ratio(&self, q: &[f64], qd: &[f64]) -> f64 {
        self.actuators.iter().fold(0.0, |m, a| m.max(a.rate(q, qd).abs() / a.max_speed))
    }

    /// The value of joint `ji` for configuration `q` (fixed: 0; mimic: follows its leader).
    #[inline]
    pub fn joint_value(&self, ji: usize, q: &[f64]) -> f64 {
        let j = &self.joints[ji];
        match (j.dof_index, j.mimic) {
            (Some(i), _) => q[i],
            (None, Some((d, m, o))) => q[d] * m + o,
            _ => 0.0,
        }
    }

    /// World poses of every link frame at `q` (index = link index).
    ///
    /// `q` must have [`Robot::dof`] values; use [`Robot::check_configuration`] on user input.
    pub fn forward_kinematics(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        let mut out = vec![Isometry3::identity(); self.links.len()];
        self.forward_kinematics_into(q, &mut out);
        out
    }

    /// [`Robot::forward_kinematics`] into a caller-owned buffer (no allocation).
    #[inline]
    pub fn forward_kinematics_into(&self, q: &[f64], out: &mut [Isometry3<f64>]) {
        debug_assert_eq!(q.len(), self.dof());
        out[0] = self.base;
        for (ji, j) in self.joints.iter().enumerate() {
            out[j.child_link] = out[j.parent_link] * j.local_transform(self.joint_value(ji, q));
        }
    }

    /// [`Robot::forward_kinematics_into`] for the links of one chain only: `chain` as
    /// [`Robot::chain_to`] gives it (root first); the poses of other links are left as they are.
    pub(crate) fn chain_kinematics_into(&self, chain: &[usize], q: &[f64], out: &mut [Isometry3<f64>]) {
        out[0] = self.base;
        for &ji in chain {
            let j = &self.joints[ji];
            out[j.child_link] = out[j.parent_link] * j.local_transform(self.joint_value(ji, q));
        }
    }

    /// World pose of one link frame at `q`.
    pub fn link_pose(&self, q: &[f64], link: usize) -> Isometry3<f64> {
        let mut pose = Isometry3::identity();
        let mut l = link;
        while let Some(ji) = self.links[l].parent_joint {
            let j = &self.joints[ji];
            pose = j.local_transform(self.joint_value(ji, q)) * pose;
            l = j.parent_link;
        }
        self.base * pose
    }

    /// Flange and tool poses of end effector `ee` at `q`.
    pub fn end_effector_poses(&self, q: &[f64], ee: usize) -> (Isometry3<f64>, Isometry3<f64>) {
        let e = &self.end_effectors[ee];
        let flange = self.link_pose(q, e.link);
        (flange, flange * e.tool)
    }

    /// Which degrees of freedom move `link` (those its chain's joints read; a mimic joint reads
    /// the one it follows), indexed like `q`.
    pub fn dofs_moving(&self, link: usize) -> Vec<bool> {
        let mut moving = vec![false; self.dof()];
        for ji in self.chain_to(link) {
            let j = &self.joints[ji];
            if let Some(i) = j.dof_index.or(j.mimic.map(|(d, _, _)| d)) {
                moving[i] = true;
            }
        }
        moving
    }

    /// The degrees of freedom in independent groups: two are in one group when some link moves
    /// with both (one joint's chain holds the other's, as along one arm), or one actuator's
    /// stroke depends on both; groups share no link they move. A robot of two arms on a fixed
    /// torso has two groups, an arm on a lifting torso one. Each group's indices ascend; the
    /// groups are ordered by their first index.
    pub fn independent_dof_groups(&self) -> &[Vec<usize>] {
        &self.dof_groups
    }

    /// [`Robot::independent_dof_groups`] once the degrees of freedom `held` (indexed like `q`;
    /// missing entries are not held) keep their values: a held one is in no group and joins
    /// none, as a fixed joint. Two arms on a lifting torso, the lift held: two groups.
    pub fn dof_groups_holding(&self, held: &[bool]) -> Vec<Vec<usize>> {
        self.group_dofs_with(held)
    }

    /// The degrees of freedom where groups of joints meet: holding one of them alone
    /// ([`Robot::dof_groups_holding`]) parts its group in two or more (a turning or lifting
    /// torso under two arms). None on a chain, an arm on a lift, or two arms on a fixed torso.
    pub fn branch_dofs(&self) -> &[usize] {
        &self.branch_dofs
    }

    /// [`Robot::independent_dof_groups`] and [`Robot::branch_dofs`] worked out.
    fn group_dofs(&self) -> (Vec<Vec<usize>>, Vec<usize>) {
        let plain = self.group_dofs_with(&[]);
        let mut held = vec![false; self.dof()];
        let mut branch = Vec::new();
        // One grouping per degree of freedom: a robot of more than `BRANCH_SEARCH_DOFS` gets none
        // (its build would take time quadratic in its size).
        let searched = if held.len() <= BRANCH_SEARCH_DOFS { held.len() } else { 0 };
        for d in 0..searched {
            held[d] = true;
            if self.group_dofs_with(&held).len() > plain.len() {
                branch.push(d);
            }
            held[d] = false;
        }
        (plain, branch)
    }

    /// [`Robot::dof_groups_holding`].
    fn group_dofs_with(&self, held: &[bool]) -> Vec<Vec<usize>> {
        let n = self.dof();
        let is_held = |d: usize| held.get(d).copied().unwrap_or(false);
        let mut parent: Vec<usize> = (0..n).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        let join = |parent: &mut Vec<usize>, a: usize, b: usize| {
            let (ra, rb) = (root(parent, a), root(parent, b));
            if ra != rb {
                parent[ra.max(rb)] = ra.min(rb);
            }
        };
        // Each joint's degree of freedom with the nearest one above it (joints come after their
        // parent link's joint): a chain's degrees of freedom end up in one group.
        let mut above: Vec<Option<usize>> = vec![None; self.links.len()];
        for j in &self.joints {
            let here = j.dof_index.or(j.mimic.map(|(d, _, _)| d)).filter(|&d| d < n && !is_held(d));
            let up = above.get(j.parent_link).copied().flatten();
            if let (Some(a), Some(d)) = (up, here) {
                join(&mut parent, a, d);
            }
            if let Some(slot) = above.get_mut(j.child_link) {
                *slot = here.or(up);
            }
        }
        for a in &self.actuators {
            let mut driven = a.angle.iter().map(|&(k, _)| k).filter(|&k| k < n && !is_held(k));
            if let Some(first) = driven.next() {
                for k in driven {
                    join(&mut parent, first, k);
                }
            }
        }
        let mut groups: Vec<Vec<usize>> = Vec::new();
        let mut index_of = vec![usize::MAX; n];
        for i in (0..n).filter(|&i| !is_held(i)) {
            let r = root(&mut parent, i);
            if index_of[r] == usize::MAX {
                index_of[r] = groups.len();
                groups.push(Vec::new());
            }
            groups[index_of[r]].push(i);
        }
        groups
    }

    /// The screws that drive some degree of freedom `i` with `which(i)` (the others' strokes do
    /// not depend on those degrees of freedom).
    pub fn actuators_driving(&self, which: impl Fn(usize) -> bool) -> Vec<&ScrewTriangle> {
        self.actuators.iter().filter(|a| a.angle.iter().any(|&(k, _)| which(k))).collect()
    }

    /// The joints on the path from the root to `link`, root first.
    pub fn chain_to(&self, link: usize) -> Vec<usize> {
        let mut chain = Vec::new();
        let mut l = link;
        while let Some(ji) = self.links[l].parent_joint {
            chain.push(ji);
            l = self.joints[ji].parent_link;
        }
        chain.reverse();
        chain
    }

    /// Geometric Jacobian (rows: linear velocity xyz, then angular velocity xyz, world frame) of
    /// the point `frame_in_link` attached to `link`, one column per degree of freedom.
    pub fn jacobian(&self, q: &[f64], link: usize, frame_in_link: &Isometry3<f64>) -> Matrix6xX<f64> {
        let poses = self.forward_kinematics(q);
        self.jacobian_with_poses(&poses, link, frame_in_link)
    }

    /// [`Robot::jacobian`] reusing link poses already computed for `q`.
    pub fn jacobian_with_poses(
        &self,
        poses: &[Isometry3<f64>],
        link: usize,
        frame_in_link: &Isometry3<f64>,
    ) -> Matrix6xX<f64> {
        let mut jac = Matrix6xX::zeros(self.dof());
        let p: Point3<f64> = (poses[link] * frame_in_link).translation.vector.into();
        let mut l = link;
        while let Some(ji) = self.links[l].parent_joint {
            let j = &self.joints[ji];
            let (dof, scale) = match (j.dof_index, j.mimic) {
                (Some(i), _) => (Some(i), 1.0),
                (None, Some((d, m, _))) => (Some(d), m),
                _ => (None, 0.0),
            };
            if let Some(dof) = dof {
                let frame = poses[j.parent_link] * j.origin;
                let axis = frame.rotation * j.axis.into_inner();
                let col: [f64; 6] = match j.kind {
                    JointKind::Revolute | JointKind::Continuous => {
                        let lin = axis.cross(&(p - Point3::from(frame.translation.vector)));
                        [lin.x, lin.y, lin.z, axis.x, axis.y, axis.z]
                    }
                    JointKind::Prismatic => [axis.x, axis.y, axis.z, 0.0, 0.0, 0.0],
                    JointKind::Fixed => [0.0; 6],
                };
                for (r, v) in col.iter().enumerate() {
                    jac[(r, dof)] += scale * v;
                }
            }
            l = j.parent_link;
        }
        jac
    }

    /// A copy of `home` as a vector.
    pub fn home_vector(&self) -> DVector<f64> {
        DVector::from_column_slice(&self.home)
    }
}

impl Robot {
    /// A copy of this robot in which the named degrees of freedom are fixed at the given values
    /// (e.g. a gripper held at its start state while the arm is planned). Mimic joints that
    /// follow a frozen joint are frozen with it.
    pub fn freeze_joints(&self, frozen: &[(&str, f64)]) -> Result<Robot, ModelError> {
        let mut robot = self.clone();
        let mut q_full = self.home.clone();
        for (name, value) in frozen {
            let Some(ji) = self.joint_index(name) else {
                return Err(ModelError::NoSuchName { robot: self.name.clone(), what: "joint", name: name.to_string() });
            };
            let Some(dof) = self.joints[ji].dof_index else {
                return Err(ModelError::Invalid {
                    robot: self.name.clone(),
                    message: format!("joint `{name}` is not a degree of freedom and cannot be frozen"),
                });
            };
            q_full[dof] = *value;
        }
        let frozen_dofs: Vec<usize> =
            frozen.iter().filter_map(|(n, _)| self.joint_index(n).and_then(|j| self.joints[j].dof_index)).collect();
        for (ji, j) in robot.joints.iter_mut().enumerate() {
            let leader = match (j.dof_index, j.mimic) {
                (Some(d), _) => Some(d),
                (None, Some((d, _, _))) => Some(d),
                _ => None,
            };
            if let Some(d) = leader
                && frozen_dofs.contains(&d)
            {
                let value = self.joint_value(ji, &q_full);
                let moved = j.local_transform(value);
                j.origin = moved * j.post.inverse();
                j.kind = JointKind::Fixed;
                j.offset = 0.0;
                j.mimic = None;
                j.dof_index = None;
            }
        }
        // Renumber the remaining degrees of freedom (and the leaders of remaining mimics).
        let old_to_new: Vec<Option<usize>> = {
            let mut next = 0;
            self.dof_joints
                .iter()
                .map(|&ji| {
                    if robot.joints[ji].kind == JointKind::Fixed {
                        None
                    } else {
                        next += 1;
                        Some(next - 1)
                    }
                })
                .collect()
        };
        robot.dof_joints =
            self.dof_joints.iter().copied().filter(|&ji| robot.joints[ji].kind != JointKind::Fixed).collect();
        for j in robot.joints.iter_mut() {
            if let Some(d) = j.dof_index {
                j.dof_index = old_to_new[d];
            }
            if let Some((d, m, o)) = j.mimic {
                j.mimic = old_to_new[d].map(|nd| (nd, m, o));
            }
        }
        // Actuators: a frozen degree of freedom's share of the drive angle becomes constant.
        for a in robot.actuators.iter_mut() {
            let mut angle = Vec::new();
            for &(d, w) in &a.angle {
                match old_to_new[d] {
                    Some(nd) => angle.push((nd, w)),
                    None => a.offset += w * q_full[d],
                }
            }
            a.angle = angle;
        }
        robot.home = self
            .dof_joints
            .iter()
            .zip(&q_full)
            .filter(|(ji, _)| robot.joints[**ji].kind != JointKind::Fixed)
            .map(|(_, v)| *v)
            .collect();
        // A closed form survives when its six joints still move; a frozen track makes it whole.
        for ee in 0..robot.closed_forms.len() {
            let resolved = robot.closed_forms[ee]
                .as_ref()
                .and_then(|c| arm_chain(&robot.links, &robot.joints, robot.end_effectors[ee].link, c.kind).ok());
            robot.closed_forms[ee] = resolved;
        }
        (robot.dof_groups, robot.branch_dofs) = robot.group_dofs();
        Ok(robot)
    }
}
