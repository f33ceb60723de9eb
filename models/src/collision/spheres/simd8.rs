//! Eight `f32` lanes on the widest vector instructions the CPU offers, chosen at run time.
//!
//! A kernel is written once, generic over [`Ops`] (the handful of lane operations the
//! single-precision batch needs), and [`dispatch`] runs it with AVX2 on CPUs that have it (one
//! 256-bit instruction per operation; `pulp` detects the features and compiles the kernel for
//! them, without `unsafe` in this crate) and with the `wide` crate's two SSE2 instructions per
//! operation on the x86-64 baseline elsewhere. Both are IEEE single-precision operations,
//! rounded to nearest; where a kernel asks for a product added to a sum ([`Ops::mul_add`]),
//! AVX2's FMA3 rounds once and the baseline twice. So the two may differ in the last bits of a
//! value, and a kernel's error bounds count the roundings of either (the kernels in `lanes`
//! settle only what is true either way; the tests run both). Fusing took 3.0% of the planning
//! instructions off (public MotionBenchMaker UR5, 90 problems, the same paths), with no change in
//! time measurable on this machine. The double-precision queries of the sphere path
//! (`SphereGeom::check`) are not dispatched: compiled for AVX2 they took 8% fewer
//! instructions but more time (eight single checks 2.2-2.5 µs against 2.06 µs on the baseline;
//! `bench mbm` p50 172 against 167 µs, interleaved), on a virtualised Xeon with AVX-512.
//!
//! Why not one build for AVX2 (`-C target-cpu=x86-64-v3`): the binary would stop with an
//! illegal instruction on CPUs without it. Why not plain `[f32; 8]` loops compiled for AVX2 by
//! the dispatch: measured, the compiler vectorised the arithmetic only in halves and built each
//! lane mask bit by bit (the planner's batches cost 7% more instructions than with `wide` on
//! SSE2, where explicit AVX2 operations cost 23% fewer).

use std::ops::{Add, AddAssign, Mul, Sub};

/// Lanes per vector.
pub(crate) const N: usize = 8;

/// Eight lanes in memory (working memory between the steps of a kernel).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(32))]
pub(crate) struct F8(pub [f32; N]);

impl F8 {
    pub(crate) const ZERO: F8 = F8([0.0; N]);
}

/// The lane operations of a kernel, for one instruction set.
pub(crate) trait Ops: Copy {
    /// A vector of eight lanes in registers.
    type V: Copy;
    /// Whether [`Ops::mul_add`] is fused here (and so `f32::mul_add` one instruction, in the
    /// plain lane loops a kernel compiled for this instruction set runs).
    const FUSED: bool;
    fn load(self, x: F8) -> Self::V;
    fn store(self, v: Self::V) -> F8;
    fn splat(self, x: f32) -> Self::V;
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    /// `a * b + c`: fused, rounded once, where the instruction set has it (AVX2 with FMA3);
    /// the product rounded, then the sum, elsewhere.
    fn mul_add(self, a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// `maxps`: the second operand where either is NaN.
    fn max(self, a: Self::V, b: Self::V) -> Self::V;
    fn abs(self, a: Self::V) -> Self::V;
    fn sqrt(self, a: Self::V) -> Self::V;
    /// Bit `i` set where lane `i` of `a` is at most `t` (never for NaN).
    fn le_mask(self, a: Self::V, t: f32) -> u32;
    /// Bit `i` set where lane `i` of `a` is at most lane `i` of `t` (never for NaN).
    fn le_mask_v(self, a: Self::V, t: Self::V) -> u32;
}

/// The x86-64 baseline (and every other target): `wide`'s `f32x8`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Base;

impl Ops for Base {
    type V = wide::f32x8;
    const FUSED: bool = false;

    #[inline(always)]
    fn load(self, x: F8) -> wide::f32x8 {
        wide::f32x8::from(x.0)
    }
    #[inline(always)]
    fn store(self, v: wide::f32x8) -> F8 {
        F8(v.to_array())
    }
    #[inline(always)]
    fn splat(self, x: f32) -> wide::f32x8 {
        wide::f32x8::splat(x)
    }
    #[inline(always)]
    fn add(self, a: wide::f32x8, b: wide::f32x8) -> wide::f32x8 {
        a + b
    }
    #[inline(always)]
    fn sub(self, a: wide::f32x8, b: wide::f32x8) -> wide::f32x8 {
        a - b
    }
    #[inline(always)]
    fn mul(self, a: wide::f32x8, b: wide::f32x8) -> wide::f32x8 {
        a * b
    }
    #[inline(always)]
    fn mul_add(self, a: wide::f32x8, b: wide::f32x8, c: wide::f32x8) -> wide::f32x8 {
        a * b + c
    }
    #[inline(always)]
    fn max(self, a: wide::f32x8, b: wide::f32x8) -> wide::f32x8 {
        a.fast_max(b)
    }
    #[inline(always)]
    fn abs(self, a: wide::f32x8) -> wide::f32x8 {
        a.abs()
    }
    #[inline(always)]
    fn sqrt(self, a: wide::f32x8) -> wide::f32x8 {
        a.sqrt()
    }
    #[inline(always)]
    fn le_mask(self, a: wide::f32x8, t: f32) -> u32 {
        use wide::CmpLe;
        a.cmp_le(wide::f32x8::splat(t)).move_mask() as u32
    }
    #[inline(always)]
    fn le_mask_v(self, a: wide::f32x8, t: wide::f32x8) -> u32 {
        use wide::CmpLe;
        a.cmp_le(t).move_mask() as u32
    }
}

#[cfg(target_arch = "x86_64")]
impl Ops for pulp::x86::V3 {
    type V = pulp::f32x8;
    const FUSED: bool = true;

    #[inline(always)]
    fn load(self, x: F8) -> pulp::f32x8 {
        pulp::cast(x.0)
    }
    #[inline(always)]
    fn store(self, v: pulp::f32x8) -> F8 {
        F8(pulp::cast(v))
    }
    #[inline(always)]
    fn splat(self, x: f32) -> pulp::f32x8 {
        self.splat_f32x8(x)
    }
    #[inline(always)]
    fn add(self, a: pulp::f32x8, b: pulp::f32x8) -> pulp::f32x8 {
        self.add_f32x8(a, b)
    }
    #[inline(always)]
    fn sub(self, a: pulp::f32x8, b: pulp::f32x8) -> pulp::f32x8 {
        self.sub_f32x8(a, b)
    }
    #[inline(always)]
    fn mul(self, a: pulp::f32x8, b: pulp::f32x8) -> pulp::f32x8 {
        self.mul_f32x8(a, b)
    }
    #[inline(always)]
    fn mul_add(self, a: pulp::f32x8, b: pulp::f32x8, c: pulp::f32x8) -> pulp::f32x8 {
        self.mul_add_f32x8(a, b, c)
    }
    #[inline(always)]
    fn max(self, a: pulp::f32x8, b: pulp::f32x8) -> pulp::f32x8 {
        self.max_f32x8(a, b)
    }
    #[inline(always)]
    fn abs(self, a: pulp::f32x8) -> pulp::f32x8 {
        self.abs_f32x8(a)
    }
    #[inline(always)]
    fn sqrt(self, a: pulp::f32x8) -> pulp::f32x8 {
        self.sqrt_f32x8(a)
    }
    #[inline(always)]
    fn le_mask(self, a: pulp::f32x8, t: f32) -> u32 {
        let m = self.cmp_le_f32x8(a, self.splat_f32x8(t));
        self.avx._mm256_movemask_ps(pulp::cast(m)) as u32
    }
    #[inline(always)]
    fn le_mask_v(self, a: pulp::f32x8, t: pulp::f32x8) -> u32 {
        let m = self.cmp_le_f32x8(a, t);
        self.avx._mm256_movemask_ps(pulp::cast(m)) as u32
    }
}

/// A vector of lanes with its instruction set, so that kernels read as arithmetic.
#[derive(Clone, Copy)]
pub(crate) struct L<O: Ops> {
    v: O::V,
    o: O,
}

impl<O: Ops> L<O> {
    #[inline(always)]
    pub(crate) fn splat(o: O, x: f32) -> Self {
        L { v: o.splat(x), o }
    }
    #[inline(always)]
    pub(crate) fn load(o: O, x: F8) -> Self {
        L { v: o.load(x), o }
    }
    #[inline(always)]
    pub(crate) fn store(self) -> F8 {
        self.o.store(self.v)
    }
    #[inline(always)]
    pub(crate) fn max(self, b: Self) -> Self {
        L { v: self.o.max(self.v, b.v), o: self.o }
    }
    /// `self * b + c` ([`Ops::mul_add`]: fused where the instruction set can).
    #[inline(always)]
    pub(crate) fn mul_add(self, b: Self, c: Self) -> Self {
        L { v: self.o.mul_add(self.v, b.v, c.v), o: self.o }
    }
    #[inline(always)]
    pub(crate) fn abs(self) -> Self {
        L { v: self.o.abs(self.v), o: self.o }
    }
    #[inline(always)]
    pub(crate) fn sqrt(self) -> Self {
        L { v: self.o.sqrt(self.v), o: self.o }
    }
    #[inline(always)]
    pub(crate) fn le_mask(self, t: f32) -> u32 {
        self.o.le_mask(self.v, t)
    }
    #[inline(always)]
    pub(crate) fn le_mask_v(self, t: Self) -> u32 {
        self.o.le_mask_v(self.v, t.v)
    }
}

impl<O: Ops> Add for L<O> {
    type Output = Self;
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        L { v: self.o.add(self.v, b.v), o: self.o }
    }
}

impl<O: Ops> AddAssign for L<O> {
    #[inline(always)]
    fn add_assign(&mut self, b: Self) {
        *self = *self + b;
    }
}

impl<O: Ops> Sub for L<O> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        L { v: self.o.sub(self.v, b.v), o: self.o }
    }
}

impl<O: Ops> Mul for L<O> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        L { v: self.o.mul(self.v, b.v), o: self.o }
    }
}

/// A computation over lanes, compiled for each instruction set [`dispatch`] may choose.
pub(crate) trait Kernel {
    type Output;
    /// The computation; implementations mark it `#[inline(always)]` so that it is compiled
    /// into the dispatch's feature-enabled function.
    fn run<O: Ops>(self, o: O) -> Self::Output;
}

/// Which instruction set [`dispatch`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Isa {
    /// The best the CPU has.
    Best,
    /// The baseline, whatever the CPU has (for tests that compare the two).
    Baseline,
}

/// Run `k` with AVX2 where the CPU has it ([`Isa::Best`]), else with the baseline.
#[inline(always)]
pub(crate) fn dispatch<K: Kernel>(k: K, isa: Isa) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    if isa == Isa::Best
        && let Some(v3) = pulp::x86::V3::try_new()
    {
        return pulp::Simd::vectorize(v3, InV3(k, v3));
    }
    let _ = isa;
    k.run(Base)
}

#[cfg(target_arch = "x86_64")]
struct InV3<K>(K, pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
impl<K: Kernel> pulp::WithSimd for InV3<K> {
    type Output = K::Output;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> K::Output {
        self.0.run(self.1)
    }
}
