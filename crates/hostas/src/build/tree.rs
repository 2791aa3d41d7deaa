//! The builders' output: an 8-wide tree over positions in the final primitive order, written
//! straight into the structure's node section in its final form ([`Node`]), so no tree is
//! kept on the heap and encoding only sums the SAH.
//!
//! The inner nodes sit in depth-first order (a node, then its children's subtrees in slot
//! order), the order of the layout. Builders reserve a node before building its children and
//! fill it in afterwards (see [`NodeList`]); subtrees built on other threads go into lists of
//! their own and are appended whole, their indices shifted.

use crate::layout::{LEAF_BIT, Node, WIDTH};
use crate::math::Aabb;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Child {
    /// Primitives `first..first + count` of the final order.
    Leaf { first: u32, count: u32 },
    /// Index of an inner node in the node list.
    Inner(u32),
}

/// Fills slot `k` (below `WIDTH`) of a node, starting from [`Node::EMPTY`], with a child and
/// its exact bounds (builders always fill all slots, see the size plan; missing ones stay
/// empty). Builders fill a node as its children are built, so no list of them is kept.
#[inline]
pub fn set_child(node: &mut Node, k: usize, b: &Aabb, c: Child) {
    let k = k & (WIDTH - 1);
    node.set_bounds(k, b);
    match c {
        Child::Leaf { first, count } => {
            node.child[k] = LEAF_BIT | first;
            node.count[k] = count as u8;
        }
        Child::Inner(i) => node.child[k] = i,
    }
}

/// A built tree: `root` covers every stored primitive (`None` when there are none); when it
/// is inner, it is node 0 of the `node_count` nodes written. `overflow` says the builder
/// needed more nodes than the section holds (a bug; encoding reports it).
#[derive(Debug)]
pub struct Tree {
    pub root: Option<(Aabb, Child)>,
    pub node_count: usize,
    pub overflow: bool,
}

enum Storage<'a> {
    /// The structure's node section.
    Section(&'a mut [Node]),
    /// A subtree built on its own, appended later.
    Owned(Vec<Node>),
}

/// Inner nodes being written in depth-first order.
pub struct NodeList<'a> {
    nodes: Storage<'a>,
    len: usize,
    overflow: bool,
}

impl<'a> NodeList<'a> {
    /// Writes into `section` (the structure's nodes).
    pub fn new(section: &'a mut [Node]) -> NodeList<'a> {
        NodeList {
            nodes: Storage::Section(section),
            len: 0,
            overflow: false,
        }
    }
    /// A list of its own, for a subtree built on another thread.
    pub fn with_capacity(n: usize) -> NodeList<'static> {
        NodeList {
            nodes: Storage::Owned(Vec::with_capacity(n)),
            len: 0,
            overflow: false,
        }
    }
    /// The tree with this list's nodes.
    pub fn tree(&self, root: Option<(Aabb, Child)>) -> Tree {
        Tree {
            root,
            node_count: self.len,
            overflow: self.overflow,
        }
    }
    fn as_slice(&self) -> &[Node] {
        match &self.nodes {
            Storage::Section(s) => &s[..self.len.min(s.len())],
            Storage::Owned(v) => v,
        }
    }
    fn push(&mut self, node: Node) {
        match &mut self.nodes {
            Storage::Section(s) => match s.get_mut(self.len) {
                Some(slot) => *slot = node,
                None => self.overflow = true,
            },
            Storage::Owned(v) => v.push(node),
        }
        self.len += 1;
    }
    /// Appends a node to be filled in by [`NodeList::set`] once its children are built.
    #[inline]
    pub fn reserve(&mut self) -> u32 {
        match &mut self.nodes {
            // Written whole by `set`: nothing to write now.
            Storage::Section(s) => self.overflow |= self.len >= s.len(),
            Storage::Owned(v) => v.push(Node::EMPTY),
        }
        self.len += 1;
        (self.len - 1) as u32
    }
    #[inline]
    pub fn set(&mut self, i: u32, node: Node) {
        let slot = match &mut self.nodes {
            Storage::Section(s) => s.get_mut(i as usize),
            Storage::Owned(v) => v.get_mut(i as usize),
        };
        if let Some(slot) = slot {
            *slot = node;
        }
    }
    /// Appends a subtree built on its own (its root, if inner, at its index 0) and returns
    /// the child as it reads in this list.
    pub fn append(&mut self, child: Child, sub: NodeList) -> Child {
        let shift = self.len as u32;
        self.overflow |= sub.overflow;
        for n in sub.as_slice() {
            let mut n = *n;
            for c in &mut n.child {
                // Leaves and empty slots (`EMPTY_CHILD`) have the leaf bit.
                if *c & LEAF_BIT == 0 {
                    *c += shift;
                }
            }
            self.push(n);
        }
        match child {
            Child::Inner(i) => Child::Inner(i + shift),
            leaf => leaf,
        }
    }
}

/// Most inner nodes a subtree over `n` primitives needs (see `layout::plan::max_nodes`), as a
/// capacity hint.
pub fn node_hint(n: usize) -> usize {
    n.saturating_sub(1).div_ceil(WIDTH - 1) + 1
}
