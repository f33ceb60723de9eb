//! SRDF (MoveIt's Semantic Robot Description Format), read as MoveIt's own parser reads it.
//!
//! Read: `<group>` (with `<chain>`, `<joint>`, `<link>`, `<group>` and `<passive_joint>`
//! members), `<group_state>` (joints with one value, or several for a multi-value joint such as
//! a floating or planar virtual joint), `<virtual_joint>`, `<end_effector>`, `<passive_joint>`,
//! `<disable_collisions>`, `<enable_collisions>` and `<disable_default_collisions>`.
//! `<link_sphere_approximation>` is known and skipped. Unknown elements and attributes are
//! warnings ([`Srdf::warnings`]), never errors. As in MoveIt's parser, a reference to a group the
//! file does not define is a warning and the referring element (subgroup, group state, end
//! effector) is dropped; [`Srdf::reconcile`] does the same for joint and link names the URDF
//! does not have. Malformed XML, a missing required attribute and a value that is not a number
//! are errors naming `file:line:column`.
//!
//! ```
//! use std::path::Path;
//! use embodied_models::srdf::parse_srdf;
//! let text = r#"<robot name="r"><group name="arm"><chain base_link="a" tip_link="c"/></group>
//!               <disable_collisions link1="a" link2="b" reason="Adjacent"/></robot>"#;
//! let srdf = parse_srdf(text, Path::new("r.srdf")).unwrap();
//! assert_eq!(srdf.groups[0].chains, vec![("a".to_string(), "c".to_string())]);
//! assert_eq!(srdf.disabled, vec![("a".to_string(), "b".to_string())]);
//! ```

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use roxmltree::Node;

use super::xml::Xml;
use crate::error::{ModelError, Warning};
use crate::robot::Robot;

/// The content of an SRDF file.
#[derive(Debug, Clone, Default)]
pub struct Srdf {
    /// The `name` of the `<robot>` element (normally the URDF's robot name; not checked).
    pub robot_name: String,
    /// Planning groups, in file order.
    pub groups: Vec<Group>,
    /// `<disable_collisions link1 link2>` pairs, in file order.
    pub disabled: Vec<(String, String)>,
    /// Where each of `disabled` is in the file (line, column; both 1-based), for warnings.
    pub disabled_at: Vec<(u32, u32)>,
    /// `<enable_collisions link1 link2>` pairs: checked even if disabled elsewhere.
    pub enabled: Vec<(String, String)>,
    /// `<disable_default_collisions link>`: links whose collisions are off by default.
    pub disabled_default: Vec<String>,
    /// Named group configurations.
    pub group_states: Vec<GroupState>,
    /// End effectors.
    pub end_effectors: Vec<SrdfEndEffector>,
    /// Virtual joints between a world frame and the robot's root.
    pub virtual_joints: Vec<VirtualJoint>,
    /// Passive joints (top level or inside a group): never planned.
    pub passive_joints: Vec<String>,
    /// What was read but not understood (unknown elements and attributes).
    pub warnings: Vec<Warning>,
    /// The file the SRDF was read from (used in error messages).
    pub file: PathBuf,
}

/// A planning group: the union of its chains, joints, links and subgroups.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Group {
    /// The group's name.
    pub name: String,
    /// `(base_link, tip_link)` of each `<chain>`.
    pub chains: Vec<(String, String)>,
    /// `<joint name>` members.
    pub joints: Vec<String>,
    /// `<link name>` members.
    pub links: Vec<String>,
    /// `<group name>` members.
    pub subgroups: Vec<String>,
    /// Line and column of the `<group>` element in [`Srdf::file`].
    pub position: (u32, u32),
}

/// A named configuration of a group (`<group_state name group>`).
#[derive(Debug, Clone, PartialEq)]
pub struct GroupState {
    /// The state's name.
    pub name: String,
    /// The group it configures.
    pub group: String,
    /// `(joint name, values)` in file order: one value for a one-degree-of-freedom joint,
    /// several for a multi-value (floating, planar) joint.
    pub values: Vec<(String, Vec<f64>)>,
    /// Line of the `<group_state>` element in [`Srdf::file`].
    pub line: u32,
    /// Column of the `<group_state>` element.
    pub column: u32,
}

/// An `<end_effector name parent_link group [parent_group]>`.
#[derive(Debug, Clone, PartialEq)]
pub struct SrdfEndEffector {
    /// The end effector's name.
    pub name: String,
    /// The link it is attached to.
    pub parent_link: String,
    /// The group of its own links and joints.
    pub group: String,
    /// The group it hangs from, if given.
    pub parent_group: Option<String>,
    /// Line of the `<end_effector>` element in [`Srdf::file`].
    pub line: u32,
    /// Column of the `<end_effector>` element.
    pub column: u32,
}

/// A `<virtual_joint name type parent_frame child_link>`.
#[derive(Debug, Clone, PartialEq)]
pub struct VirtualJoint {
    /// The joint's name.
    pub name: String,
    /// `fixed`, `floating` or `planar`.
    pub kind: String,
    /// The outside frame (e.g. `world`, `odom_combined`).
    pub parent_frame: String,
    /// The robot's root link.
    pub child_link: String,
}

/// Read and parse an SRDF file.
pub fn load_srdf(path: &Path) -> Result<Srdf, ModelError> {
    let text = super::limits::read_text_limited(path, super::limits::InputKind::Text)
        .map_err(|source| ModelError::Io { file: path.to_path_buf(), source })?;
    parse_srdf(&text, path)
}

/// The attributes MoveIt's parser reads on each element; others are warned about.
fn known_attributes(tag: &str) -> &'static [&'static str] {
    match tag {
        "robot" => &["name"],
        "group" | "joint" | "link" | "passive_joint" => &["name"],
        "chain" => &["base_link", "tip_link"],
        "group_state" => &["name", "group"],
        "end_effector" => &["name", "parent_link", "group", "parent_group"],
        "virtual_joint" => &["name", "type", "parent_frame", "child_link"],
        "disable_collisions" | "enable_collisions" => &["link1", "link2", "reason"],
        "disable_default_collisions" => &["link"],
        _ => &[],
    }
}

struct Reader<'x, 'i> {
    x: &'x Xml<'i>,
    warnings: Vec<Warning>,
}

impl Reader<'_, '_> {
    fn warn(&mut self, node: Node, message: String) {
        let (line, column) = self.x.position(node);
        self.warnings.push(Warning { file: self.x.file.clone(), line, column, message });
    }

    /// Warn about attributes of `node` the SRDF format does not define.
    fn check_attributes(&mut self, node: Node) {
        let tag = node.tag_name().name();
        let known = known_attributes(tag);
        for a in node.attributes() {
            if a.namespace().is_none() && !known.contains(&a.name()) {
                self.warn(
                    node,
                    format!("unknown attribute `{}` on <{tag}> ignored (expected: {})", a.name(), known.join(", ")),
                );
            }
        }
    }
}

/// Parse SRDF text; `file` is used in error messages.
pub fn parse_srdf(text: &str, file: &Path) -> Result<Srdf, ModelError> {
    let doc = Xml::parse(text, file)?;
    let x = &doc;
    let mut r = Reader { x, warnings: Vec::new() };
    let root = doc.doc.root_element();
    if root.tag_name().name() != "robot" {
        return Err(x.err(root, format!("expected a <robot> root element, found <{}>", root.tag_name().name())));
    }
    r.check_attributes(root);
    let mut srdf = Srdf {
        robot_name: root.attribute("name").unwrap_or_default().to_string(),
        file: file.to_path_buf(),
        ..Srdf::default()
    };
    // Group references are checked once every group is known.
    let mut references: Vec<(Node, String, Reference)> = Vec::new();
    for node in root.children().filter(|n| n.is_element()) {
        let tag = node.tag_name().name();
        if !known_attributes(tag).is_empty() {
            r.check_attributes(node);
        }
        match tag {
            "group" => {
                let name = x.attr(node, "name", "the group's name")?.to_string();
                if srdf.groups.iter().any(|g| g.name == name) {
                    return Err(x.err(node, format!("a second group named `{name}` (group names must be unique)")));
                }
                let mut group = Group { name, position: x.position(node), ..Group::default() };
                for member in node.children().filter(|n| n.is_element()) {
                    r.check_attributes(member);
                    match member.tag_name().name() {
                        "chain" => group.chains.push((
                            x.attr(member, "base_link", "the chain's base link name")?.to_string(),
                            x.attr(member, "tip_link", "the chain's tip link name")?.to_string(),
                        )),
                        "joint" => group.joints.push(x.attr(member, "name", "a joint name")?.to_string()),
                        "link" => group.links.push(x.attr(member, "name", "a link name")?.to_string()),
                        "group" => {
                            let sub = x.attr(member, "name", "a group name")?.to_string();
                            references.push((member, sub.clone(), Reference::Subgroup(srdf.groups.len())));
                            group.subgroups.push(sub);
                        }
                        "passive_joint" => {
                            srdf.passive_joints.push(x.attr(member, "name", "a joint name")?.to_string());
                        }
                        other => r.warn(
                            member,
                            format!(
                                "unknown <{other}> in <group> ignored (expected <chain>, <joint>, <link>, <group> or <passive_joint>)"
                            ),
                        ),
                    }
                }
                srdf.groups.push(group);
            }
            "group_state" => {
                let name = x.attr(node, "name", "the state's name")?.to_string();
                let group = x.attr(node, "group", "the name of a group")?.to_string();
                references.push((node, group.clone(), Reference::State(srdf.group_states.len())));
                let mut values = Vec::new();
                for j in node.children().filter(|n| n.is_element()) {
                    if j.tag_name().name() != "joint" {
                        r.warn(
                            j,
                            format!("unknown <{}> in <group_state> ignored (expected <joint>)", j.tag_name().name()),
                        );
                        continue;
                    }
                    r.check_attributes_of_state_joint(j);
                    let joint = x.attr(j, "name", "a joint name")?.to_string();
                    let text = x.attr(j, "value", "one number, or several for a multi-value joint")?;
                    let n = text.split_whitespace().count().max(1);
                    let v = x.numbers(j, "value", text, n, "numbers (radians or metres)")?;
                    values.push((joint, v));
                }
                let (line, column) = x.position(node);
                srdf.group_states.push(GroupState { name, group, values, line, column });
            }
            "end_effector" => {
                let group = x.attr(node, "group", "the name of the end effector's group")?.to_string();
                references.push((node, group.clone(), Reference::EndEffector(srdf.end_effectors.len())));
                let parent_group = match node.attribute("parent_group") {
                    Some(g) => {
                        references.push((node, g.to_string(), Reference::ParentGroup(srdf.end_effectors.len())));
                        Some(g.to_string())
                    }
                    None => None,
                };
                let (line, column) = x.position(node);
                srdf.end_effectors.push(SrdfEndEffector {
                    name: x.attr(node, "name", "the end effector's name")?.to_string(),
                    parent_link: x.attr(node, "parent_link", "the link the end effector is attached to")?.to_string(),
                    group,
                    parent_group,
                    line,
                    column,
                });
            }
            "virtual_joint" => {
                let kind = x.attr(node, "type", "fixed, floating or planar")?;
                if !matches!(kind, "fixed" | "floating" | "planar") {
                    return Err(
                        x.err(node, format!("virtual joint type `{kind}` (expected fixed, floating or planar)"))
                    );
                }
                srdf.virtual_joints.push(VirtualJoint {
                    name: x.attr(node, "name", "the virtual joint's name")?.to_string(),
                    kind: kind.to_string(),
                    parent_frame: x.attr(node, "parent_frame", "the outside frame's name")?.to_string(),
                    child_link: x.attr(node, "child_link", "the robot's root link")?.to_string(),
                });
            }
            "passive_joint" => srdf.passive_joints.push(x.attr(node, "name", "a joint name")?.to_string()),
            "disable_collisions" => {
                srdf.disabled.push((
                    x.attr(node, "link1", "a link name")?.to_string(),
                    x.attr(node, "link2", "a link name")?.to_string(),
                ));
                srdf.disabled_at.push(x.position(node));
            }
            "enable_collisions" => srdf.enabled.push((
                x.attr(node, "link1", "a link name")?.to_string(),
                x.attr(node, "link2", "a link name")?.to_string(),
            )),
            "disable_default_collisions" => {
                srdf.disabled_default.push(x.attr(node, "link", "a link name")?.to_string());
            }
            "link_sphere_approximation" => {}
            other => r.warn(node, format!("unknown SRDF element <{other}> ignored")),
        }
    }
    let known: Vec<String> = srdf.groups.iter().map(|g| g.name.clone()).collect();
    let (mut drop_states, mut drop_effectors) = (Vec::new(), Vec::new());
    for (node, name, what) in references {
        if known.contains(&name) {
            continue;
        }
        let dropped = match what {
            Reference::Subgroup(g) => {
                srdf.groups[g].subgroups.retain(|s| *s != name);
                "subgroup ignored"
            }
            Reference::State(i) => {
                drop_states.push(i);
                "group state ignored"
            }
            Reference::EndEffector(i) => {
                drop_effectors.push(i);
                "end effector ignored"
            }
            Reference::ParentGroup(i) => {
                srdf.end_effectors[i].parent_group = None;
                "parent group ignored"
            }
        };
        r.warn(
            node,
            format!(
                "unknown group `{name}`, {dropped} (expected one of the groups defined in the file: {})",
                known.join(", ")
            ),
        );
    }
    let mut k = 0;
    srdf.group_states.retain(|_| {
        k += 1;
        !drop_states.contains(&(k - 1))
    });
    let mut k = 0;
    srdf.end_effectors.retain(|_| {
        k += 1;
        !drop_effectors.contains(&(k - 1))
    });
    srdf.warnings = r.warnings;
    Ok(srdf)
}

/// What refers to a group, to drop it if the group is unknown.
#[derive(Clone, Copy)]
enum Reference {
    Subgroup(usize),
    State(usize),
    EndEffector(usize),
    ParentGroup(usize),
}

impl Reader<'_, '_> {
    fn check_attributes_of_state_joint(&mut self, node: Node) {
        for a in node.attributes() {
            if a.namespace().is_none() && !matches!(a.name(), "name" | "value") {
                self.warn(node, format!("unknown attribute `{}` on <joint> ignored (expected: name, value)", a.name()));
            }
        }
    }
}

impl Srdf {
    /// A group by name.
    pub fn group(&self, name: &str) -> Option<&Group> {
        self.groups.iter().find(|g| g.name == name)
    }

    /// A group state by name (the first if several groups use the name).
    pub fn group_state(&self, name: &str) -> Option<&GroupState> {
        self.group_states.iter().find(|s| s.name == name)
    }

    /// The active joints (degrees of freedom of `robot`: not fixed, not mimic) of a group, in
    /// the robot's `q` order.
    ///
    /// Passive joints and the SRDF's virtual joints are left out. Membership follows MoveIt: a `<chain>` contributes the joints on the tree path from its
    /// base link down to its tip link (the base link must be an ancestor of the tip); a
    /// `<joint>` itself; a `<link>` its parent joint; a `<group>` its own joints, recursively.
    pub fn group_joints(&self, robot: &Robot, group: &str) -> Result<Vec<String>, ModelError> {
        let mut joints = BTreeSet::new();
        let mut stack = Vec::new();
        self.collect_joints(robot, group, &mut stack, &mut joints)?;
        let mut dofs: Vec<usize> = joints
            .into_iter()
            .filter(|&j| !self.passive_joints.contains(&robot.joints()[j].name))
            .filter_map(|j| robot.joints()[j].dof_index)
            .collect();
        dofs.sort_unstable();
        dofs.dedup();
        Ok(dofs.into_iter().map(|d| robot.dof_joint(d).name.clone()).collect())
    }

    /// Like [`Srdf::group_joints`] but the indices of the degrees of freedom in `q`.
    pub fn group_dofs(&self, robot: &Robot, group: &str) -> Result<Vec<usize>, ModelError> {
        let names = self.group_joints(robot, group)?;
        Ok(names.iter().filter_map(|n| robot.joint_index(n).and_then(|j| robot.joints()[j].dof_index)).collect())
    }

    fn collect_joints<'s>(
        &'s self,
        robot: &Robot,
        group: &'s str,
        stack: &mut Vec<&'s str>,
        out: &mut BTreeSet<usize>,
    ) -> Result<(), ModelError> {
        let invalid = |message: String| ModelError::Invalid { robot: robot.name().to_string(), message };
        let Some(g) = self.group(group) else {
            let known: Vec<&str> = self.groups.iter().map(|g| g.name.as_str()).collect();
            return Err(invalid(format!(
                "SRDF {} has no group `{group}` (expected one of: {})",
                self.file.display(),
                known.join(", ")
            )));
        };
        if stack.contains(&group) {
            return Err(invalid(format!(
                "SRDF {}: group `{group}` contains itself through its subgroups ({} -> {group})",
                self.file.display(),
                stack.join(" -> ")
            )));
        }
        stack.push(group);
        let link = |name: &str| {
            robot.link_index(name).ok_or_else(|| ModelError::NoSuchName {
                robot: robot.name().to_string(),
                what: "link",
                name: name.to_string(),
            })
        };
        for (base, tip) in &g.chains {
            let (base_i, tip_i) = (link(base)?, link(tip)?);
            let chain = robot.chain_to(tip_i);
            // Joints below the base link: those after the base link's own parent joint.
            let start = match robot.links()[base_i].parent_joint {
                None => Some(0),
                Some(bj) => chain.iter().position(|&j| j == bj).map(|p| p + 1),
            };
            let Some(start) = start else {
                return Err(invalid(format!(
                    "SRDF {}: group `{group}` has a chain from `{base}` to `{tip}`, but `{base}` is not an ancestor of `{tip}`",
                    self.file.display()
                )));
            };
            out.extend(&chain[start..]);
        }
        // A virtual joint (world to root) is not a joint of the URDF: nothing to plan there.
        for j in g.joints.iter().filter(|j| !self.is_virtual_joint(j)) {
            let ji = robot.joint_index(j).ok_or_else(|| ModelError::NoSuchName {
                robot: robot.name().to_string(),
                what: "joint",
                name: j.clone(),
            })?;
            out.insert(ji);
        }
        for l in &g.links {
            if let Some(pj) = robot.links()[link(l)?].parent_joint {
                out.insert(pj);
            }
        }
        for sub in &g.subgroups {
            self.collect_joints(robot, sub, stack, out)?;
        }
        stack.pop();
        Ok(())
    }
}

/// Apply the SRDF's collision settings to `robot`: every `<disable_collisions>` pair and every
/// pair with a `<disable_default_collisions>` link is disabled, then `<enable_collisions>` pairs
/// are enabled again (pairs naming links the robot does not have are skipped, as MoveIt does).
pub fn apply_srdf(robot: &mut Robot, srdf: &Srdf) {
    for (a, b) in srdf.disabled_pairs(robot) {
        robot.disable_pair(a, b);
    }
}

impl Srdf {
    /// The link index pairs `(a, b)` with `a < b` whose collisions the SRDF turns off for
    /// `robot`, after `<disable_default_collisions>` and `<enable_collisions>`.
    pub fn disabled_pairs(&self, robot: &Robot) -> Vec<(usize, usize)> {
        let idx = |n: &str| robot.link_index(n);
        let ordered = |a: usize, b: usize| (a.min(b), a.max(b));
        let mut out = BTreeSet::new();
        for (a, b) in &self.disabled {
            if let (Some(a), Some(b)) = (idx(a), idx(b))
                && a != b
            {
                out.insert(ordered(a, b));
            }
        }
        for l in &self.disabled_default {
            if let Some(a) = idx(l) {
                for b in (0..robot.links().len()).filter(|&b| b != a) {
                    out.insert(ordered(a, b));
                }
            }
        }
        for (a, b) in &self.enabled {
            if let (Some(a), Some(b)) = (idx(a), idx(b)) {
                out.remove(&ordered(a, b));
            }
        }
        out.into_iter().collect()
    }

    /// Drop what names joints or links `robot` does not have (group members, chains, group
    /// state values), as MoveIt does when it reads an SRDF against its URDF, and return one
    /// warning per dropped name (also appended to [`Srdf::warnings`]).
    pub fn reconcile(&mut self, robot: &Robot) -> Vec<Warning> {
        let mut out = Vec::new();
        let file = self.file.clone();
        let mut warn = |(line, column): (u32, u32), message: String| {
            out.push(Warning { file: file.clone(), line, column, message });
        };
        let virtuals: Vec<String> = self.virtual_joints.iter().map(|v| v.name.clone()).collect();
        let joint_ok = |j: &String| virtuals.contains(j) || robot.joint_index(j).is_some();
        for g in &mut self.groups {
            for j in g.joints.iter().filter(|j| !joint_ok(j)) {
                warn(g.position, format!("group `{}`: joint `{j}` is not in the URDF, ignored", g.name));
            }
            g.joints.retain(|j| joint_ok(j));
            for l in g.links.iter().filter(|l| robot.link_index(l).is_none()) {
                warn(g.position, format!("group `{}`: link `{l}` is not in the URDF, ignored", g.name));
            }
            g.links.retain(|l| robot.link_index(l).is_some());
            for (b, t) in
                g.chains.iter().filter(|(b, t)| robot.link_index(b).is_none() || robot.link_index(t).is_none())
            {
                warn(
                    g.position,
                    format!("group `{}`: chain `{b}` -> `{t}` names a link not in the URDF, ignored", g.name),
                );
            }
            g.chains.retain(|(b, t)| robot.link_index(b).is_some() && robot.link_index(t).is_some());
        }
        // A pair naming a link the URDF lacks disables nothing (kept, as MoveIt keeps it in its
        // matrix): said once per name, at its first pair, so that a misspelt link does not
        // leave a pair checked unnoticed (and a URDF that leaves links out is not a flood).
        let mut missing: Vec<(&str, (u32, u32), usize)> = Vec::new();
        for (k, (a, b)) in self.disabled.iter().enumerate() {
            let at = self.disabled_at.get(k).copied().unwrap_or((0, 0));
            for l in [a, b].into_iter().filter(|l| robot.link_index(l).is_none()) {
                match missing.iter_mut().find(|(name, _, _)| *name == l.as_str()) {
                    Some((_, _, count)) => *count += 1,
                    None => missing.push((l, at, 1)),
                }
            }
        }
        for (l, at, count) in missing {
            let pairs = if count == 1 {
                "its disable_collisions pair is".to_string()
            } else {
                format!("its {count} disable_collisions pairs are")
            };
            warn(at, format!("link `{l}` is not in the URDF: {pairs} ignored"));
        }
        for s in &mut self.group_states {
            for (j, _) in s.values.iter().filter(|(j, _)| !joint_ok(j)) {
                warn((s.line, s.column), format!("group state `{}`: joint `{j}` is not in the URDF, ignored", s.name));
            }
            s.values.retain(|(j, _)| joint_ok(j));
        }
        self.warnings.extend(out.iter().cloned());
        out
    }

    /// The names of the SRDF's virtual joints (not joints of the URDF).
    pub fn is_virtual_joint(&self, name: &str) -> bool {
        self.virtual_joints.iter().any(|v| v.name == name)
    }
}
