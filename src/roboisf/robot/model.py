"""The robot model: geometry + joint limits + joint stiffness + tool, kept apart from per-call data.

A :class:`RobotModel` is immutable and validated at construction. Per-call inputs (joint angles,
wrenches) are plain arrays; every method is batched over a leading axis N.

Conventions
-----------
* ``q`` (N, 6) rad in the **controller's own convention** (what the robot logs and shows on the
  pendant). The map to the model angles is ``θ = sign·q + offset`` (see
  :mod:`roboisf.robot.kinematics`); it is stored with the preset and tested against an
  independent OPW implementation (py-opw-kinematics).
* The **flange frame** has z out of the flange (ABB ``tool0``). ``T_flange_tip`` places the tool
  tip; with no tool the tip is the flange.
* Jacobian, compliance and deflection are at the tool tip, expressed in the base frame, ordered
  ``[linear; angular]``. Wrenches are those *applied to the tool* at the tip ``[f; m]`` (N, N·m);
  the deflection ``[δ; θ]`` (m, rad) is the tip's small displacement they cause.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError, short_indices
from roboisf.frames.se3 import check_rigid
from roboisf.progress import Progress
from roboisf.robot import vjm_kernel
from roboisf.robot.kinematics import (
    Chain,
    OPWGeometry,
    chain_fk,
    chain_fk_jacobian,
    chain_from_opw,
    opw_fk_jacobian,
    rotate_6,
    rotate_6x6,
)

__all__ = ["RobotModel"]

F64 = NDArray[np.float64]

#: Rows per block of :meth:`RobotModel.tip_positions`' numpy path.
_FK_BLOCK = 32_768


def _ro(a: ArrayLike, shape: tuple[int, ...], name: str) -> F64:
    arr = np.array(a, dtype=float)
    if arr.shape != shape:
        raise InputError(f"expected shape {shape}, got {arr.shape}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A 6R serial robot for elastostatics.

    Attributes
    ----------
    name : str
    chain : Chain — kinematic geometry (controller convention included)
    q_min, q_max : (6,) float, rad — joint limits (controller convention)
    stiffness : (6,) float, N·m/rad, or None when not known (FK/IK work, compliance refuses)
    T_flange_tip : (4, 4) float — tool tip in the flange frame (m)
    opw : OPWGeometry or None — set for ortho-parallel robots; enables closed-form IK
    default_placement : (4, 4) float or None — a sensible ``T_base_work`` for this robot
    source : str — where the numbers come from
    T_flange_link : (4, 4) float — the robot file's tip link in the model's flange frame:
        identity, unless a URDF's tip link is not an OPW flange (:func:`roboisf.robot.load_urdf`
        then puts the flange on axis 6); :meth:`with_tool` takes tools in the tip link's frame
    ik_note : str — why the robot has no closed-form IK ("" when it has, or is a preset); said
        whenever :func:`~roboisf.robot.ik.ik_toolpath` falls back to numerical IK
    backend : VJM engine of :meth:`compliance`, :meth:`deflection` and
        :func:`~roboisf.robot.vjm_batch`: ``"auto"`` (default: ``"numba"`` when numba is
        installed and not switched off, else ``"numpy"``), ``"numba"`` (fused compiled
        kernel, built at install) or ``"numpy"`` (chunked vectorised numpy); same numbers to ≤ 1e-14
        relative (:mod:`roboisf.robot.vjm_kernel`). A choice of the run, not saved with the robot.
    """

    name: str
    chain: Chain
    q_min: F64
    q_max: F64
    stiffness: F64 | None = None
    T_flange_tip: F64 = field(default_factory=lambda: np.eye(4))
    opw: OPWGeometry | None = None
    default_placement: F64 | None = None
    source: str = ""
    stiffness_source: str = ""
    backend: str = "auto"
    T_flange_link: F64 = field(default_factory=lambda: np.eye(4))
    ik_note: str = ""

    def __post_init__(self) -> None:
        vjm_kernel.check_backend(self.backend)
        q_min = _ro(self.q_min, (6,), "q_min")
        q_max = _ro(self.q_max, (6,), "q_max")
        if np.any(q_min >= q_max):
            bad = [i + 1 for i in np.flatnonzero(q_min >= q_max)]
            raise InputError(f"joint limits need q_min < q_max (joints {bad})", field="limits")
        object.__setattr__(self, "q_min", q_min)
        object.__setattr__(self, "q_max", q_max)
        if self.stiffness is not None:
            K = _ro(self.stiffness, (6,), "stiffness")
            if np.any(K <= 0):
                bad = [i + 1 for i in np.flatnonzero(K <= 0)]
                raise InputError(
                    f"joint stiffness must be > 0 N·m/rad, got {K.tolist()} (joints {bad})",
                    field="stiffness",
                )
            object.__setattr__(self, "stiffness", K)
        T = _ro(self.T_flange_tip, (4, 4), "T_flange_tip")
        check_rigid(T, "T_flange_tip")
        object.__setattr__(self, "T_flange_tip", T)
        L = _ro(self.T_flange_link, (4, 4), "T_flange_link")
        check_rigid(L, "T_flange_link")
        object.__setattr__(self, "T_flange_link", L)
        if self.opw is not None:
            ref = chain_from_opw(self.opw)
            if np.max(np.abs(ref.F - self.chain.F)) > 1e-12:
                raise InputError("chain does not match the OPW parameters", field="chain")
        if self.default_placement is not None:
            P = _ro(self.default_placement, (4, 4), "default_placement")
            check_rigid(P, "default_placement")
            object.__setattr__(self, "default_placement", P)

    # ------------------------------------------------------------------ construction
    def with_tool(self, T_flange_tip: ArrayLike) -> RobotModel:
        """A copy with the tool tip at ``T_flange_tip`` (4, 4) in the flange frame (m) — the
        robot file's tip link (:attr:`T_flange_link`; the flange itself for presets)."""
        T = self.T_flange_link @ np.asarray(T_flange_tip, dtype=float)
        return replace(self, T_flange_tip=T)

    def with_stiffness(self, K: ArrayLike, source: str = "user") -> RobotModel:
        """A copy with joint stiffness ``K`` (6,) N·m/rad."""
        return replace(self, stiffness=np.asarray(K, dtype=float), stiffness_source=source)

    def with_backend(self, backend: str) -> RobotModel:
        """A copy whose VJM runs on ``backend`` ("auto", "numba" or "numpy")."""
        return replace(self, backend=backend)

    @property
    def joint_stiffness(self) -> F64:
        """K_θ (6,) N·m/rad; raises :class:`InputError` when the model has none."""
        if self.stiffness is None:
            raise InputError(
                f"robot {self.name!r} has no joint stiffness (no published value); identify it "
                "(`roboisf robot identify`) or set it with model.with_stiffness(K) / "
                "--stiffness stiffness.toml",
                field="stiffness",
            )
        return self.stiffness

    # ------------------------------------------------------------------ validation
    def check_q(self, q: ArrayLike, *, limits: bool = True, field: str = "q") -> F64:
        """Validate joint angles → (N, 6) float rad. Accepts (6,) for a single pose."""
        arr = np.asarray(q, dtype=float)
        if arr.ndim == 1:
            arr = arr[None, :]
        if arr.ndim != 2 or arr.shape[1] != 6:
            raise InputError(
                f"expected joint angles of shape (N, 6) for a 6-axis robot, got {arr.shape}",
                field=field,
            )
        if not np.isfinite(arr).all():  # one pass; the rows only for the message
            idx = np.flatnonzero(~np.all(np.isfinite(arr), axis=1))
            raise InputError(
                f"joint angles contain NaN or inf at rows {short_indices(idx)}", field=field
            )
        if limits:
            tol = 1e-9
            out = (arr < self.q_min - tol) | (arr > self.q_max + tol)
            if np.any(out):
                rows, cols = np.nonzero(out)
                j = cols[0]
                raise InputError(
                    f"joint angles beyond the limits of {self.name} at rows {short_indices(rows)}: "
                    f"e.g. row {rows[0]} A{j + 1} = {np.degrees(arr[rows[0], j]):.3f} deg, "
                    f"limits [{np.degrees(self.q_min[j]):.1f}, "
                    f"{np.degrees(self.q_max[j]):.1f}] deg",
                    field=field,
                )
        return arr

    # ------------------------------------------------------------------ kinematics
    def fk(
        self, q: ArrayLike, *, check_limits: bool = True, T_base_work: ArrayLike | None = None
    ) -> F64:
        """``T_base_tip`` (N, 4, 4) for ``q`` (N, 6) rad; ``T_work_tip`` when ``T_base_work``."""
        qv = self.check_q(q, limits=check_limits)
        if self.opw is not None:
            Topt, _ = opw_fk_jacobian(
                self.opw, self.chain, qv, self.T_flange_tip, want_jacobian=False
            )
            assert Topt is not None
            T = Topt
        else:
            T = chain_fk(self.chain, qv, self.T_flange_tip)
        if T_base_work is not None:
            T = np.linalg.inv(_placement(T_base_work)) @ T
        return T

    def tip_positions(
        self,
        q: ArrayLike,
        *,
        check_limits: bool = True,
        T_base_work: ArrayLike | None = None,
        backend: str | None = None,
    ) -> F64:
        """Tool-tip positions (N, 3) [m] for ``q`` (N, 6) rad: base frame, or the work frame
        when ``T_base_work`` (4, 4) is given; ``fk(q)[:, :3, 3]`` without the rotations.

        With numba (``backend`` "auto"/"numba", default :attr:`backend`) one compiled pass
        (:mod:`roboisf.robot.fk_numba`: no (N, 4, 4) array, ~10× faster for a whole joint log);
        the same positions as :meth:`fk` to rounding (≤ 1e-12 m, tested).
        """
        qv = self.check_q(q, limits=check_limits)
        b = self.backend if backend is None else vjm_kernel.check_backend(backend)
        # the C form (fk_numba.tip_positions calls it) needs neither numba nor group "robot"
        if not (vjm_kernel.use_c(b) or vjm_kernel.use_numba(b)):
            # in blocks: each row's FK is elementwise, so the same numbers as one call, but the
            # ~40 temporaries of a block stay in cache and are reused instead of faulting fresh
            # pages in (a 573 k-sample joint log: 0.30–0.79 → 0.15–0.17 s)
            out = np.empty((qv.shape[0], 3))
            for i in range(0, qv.shape[0], _FK_BLOCK):
                Tb = self.fk(qv[i : i + _FK_BLOCK], check_limits=False, T_base_work=T_base_work)
                out[i : i + _FK_BLOCK] = Tb[:, :3, 3]
            return out
        from roboisf.robot import fk_numba

        F = self.chain.F.copy()
        F[6] = F[6] @ self.T_flange_tip
        T = np.eye(4) if T_base_work is None else np.linalg.inv(_placement(T_base_work))
        return fk_numba.tip_positions(
            F, self.chain.sign, self.chain.offset, self.chain.couple23, np.asarray(T, float), qv
        )

    def fk_jacobian(self, q: ArrayLike, *, check_limits: bool = True) -> tuple[F64, F64]:
        """``(T_base_tip (N, 4, 4), J (N, 6, 6))`` in one pass (closed form for OPW robots)."""
        return self._fk_jacobian(self.check_q(q, limits=check_limits))

    def _fk_jacobian(self, qv: F64) -> tuple[F64, F64]:
        if self.opw is not None:
            T, J = opw_fk_jacobian(self.opw, self.chain, qv, self.T_flange_tip)
            assert T is not None and J is not None
            return T, J
        return chain_fk_jacobian(self.chain, qv, self.T_flange_tip)

    def _jacobian_only(self, qv: F64) -> F64:
        """Jacobian of validated angles without assembling T (the hot path of vjm_batch)."""
        if self.opw is not None:
            _, J = opw_fk_jacobian(self.opw, self.chain, qv, self.T_flange_tip, want_fk=False)
            assert J is not None
            return J
        return chain_fk_jacobian(self.chain, qv, self.T_flange_tip)[1]

    def jacobian(
        self, q: ArrayLike, *, check_limits: bool = True, T_base_work: ArrayLike | None = None
    ) -> F64:
        """Geometric Jacobian at the tool tip (N, 6, 6), rows [v (m/rad); ω (1)].

        Base axes, or work axes when ``T_base_work`` (4, 4) is given (same tip point).
        """
        J = self.fk_jacobian(q, check_limits=check_limits)[1]
        if T_base_work is None:
            return J
        R_wb = _placement(T_base_work)[:3, :3].T
        out = np.empty_like(J)
        out[:, :3] = np.einsum("ij,njk->nik", R_wb, J[:, :3])
        out[:, 3:] = np.einsum("ij,njk->nik", R_wb, J[:, 3:])
        return out

    # ------------------------------------------------------------------ elastostatics
    def compliance(
        self,
        q: ArrayLike,
        *,
        check_limits: bool = True,
        T_base_work: ArrayLike | None = None,
        backend: str | None = None,
    ) -> F64:
        """VJM Cartesian compliance ``k_c = J K_θ⁻¹ Jᵀ`` (N, 6, 6) at the tip.

        Base axes, or work axes when ``T_base_work`` is given. Blocks: [:3, :3] m/N,
        off-diagonal 1/N, [3:, 3:] rad/(N·m). ``backend`` overrides :attr:`backend` for this
        call. Chunked: the only memory is the result.
        """
        qv = self.check_q(q, limits=check_limits)
        k = self.vjm(qv, np.zeros(6), want_compliance=True, backend=backend).k
        assert k is not None
        if T_base_work is not None:
            k = rotate_6x6(k, _placement(T_base_work)[:3, :3].T)
        return k

    def deflection(
        self,
        q: ArrayLike,
        wrench: ArrayLike,
        *,
        check_limits: bool = True,
        T_base_work: ArrayLike | None = None,
        backend: str | None = None,
    ) -> F64:
        """Tip deflection ``[δ; θ] = k_c W`` (N, 6) [m; rad] for tip wrenches (N, 6) [N; N·m].

        Wrench and deflection in base axes, or both in work axes when ``T_base_work`` is given;
        a single (6,) wrench is broadcast. ``backend`` overrides :attr:`backend` for this call.
        Chunked and fused (FK, Jacobian, ``τ = JᵀW``, ``δ = J K_θ⁻¹ τ`` per pose): the only
        memory is the result.
        """
        qv = self.check_q(q, limits=check_limits)
        W = _check_wrench(wrench, qv.shape[0])
        if T_base_work is not None:
            W = rotate_6(W, _placement(T_base_work)[:3, :3])
        d = self.vjm(qv, W, backend=backend).d
        if T_base_work is not None:
            d = rotate_6(d, _placement(T_base_work)[:3, :3].T)
        return d

    def vjm(
        self,
        qv: F64,
        W: F64,
        *,
        want_compliance: bool = False,
        want_jacobian: bool = False,
        margin: tuple[float, float] | None = None,
        backend: str | None = None,
        chunk: int = vjm_kernel.CHUNK,
        progress: Progress | None = None,
    ) -> vjm_kernel.VJMResult:
        """``VJMResult(d (N, 6), k (N, 6, 6), J (N, 6, 6), margin_ok (N,))`` at the tip, base axes.

        The one VJM path (:func:`roboisf.robot.vjm_kernel.vjm_eval`) for already validated
        angles ``qv`` (N, 6) rad (:meth:`check_q`) and wrenches ``W`` (N, 6) or (6,) [N; N·m],
        base axes. ``k``, ``J`` and ``margin_ok`` (the singularity-margin test for ``margin`` =
        (length scale m, threshold), :func:`roboisf.robot.singularity.margin_ok`) are computed
        only when asked, else None; ``chunk``: poses per chunk of the numpy engine.
        """
        return self._vjm(
            qv,
            W,
            1.0 / self.joint_stiffness,
            want_compliance=want_compliance,
            want_jacobian=want_jacobian,
            margin=margin,
            backend=backend,
            chunk=chunk,
            progress=progress,
        )

    def singularity_margin_ok(
        self, qv: F64, length_scale: float, threshold: float, *, backend: str | None = None
    ) -> NDArray[np.bool_]:
        """(N,) bool: ``σ_min(J_s) > threshold`` for validated angles ``qv`` (N, 6) rad, ``J_s``
        the tip Jacobian with its linear rows divided by ``length_scale`` (m).

        The exact elimination test of :func:`roboisf.robot.singularity.margin_ok`, run in the
        fused kernel without materialising the Jacobians; needs no joint stiffness.
        """
        ok = self._vjm(
            qv, np.zeros(6), np.ones(6), margin=(length_scale, threshold), backend=backend
        ).margin_ok
        assert ok is not None
        return ok

    def _vjm(
        self,
        qv: F64,
        W: F64,
        kinv: F64,
        *,
        want_compliance: bool = False,
        want_jacobian: bool = False,
        margin: tuple[float, float] | None = None,
        backend: str | None = None,
        chunk: int = vjm_kernel.CHUNK,
        progress: Progress | None = None,
    ) -> vjm_kernel.VJMResult:
        b = self.backend if backend is None else vjm_kernel.check_backend(backend)
        F = self.chain.F.copy()
        F[6] = F[6] @ self.T_flange_tip
        Wv = _check_wrench(W, qv.shape[0])
        return vjm_kernel.vjm_eval(
            F,
            self.chain.sign,
            self.chain.offset,
            kinv,
            qv,
            Wv,
            self._jacobian_only,
            want_compliance=want_compliance,
            want_jacobian=want_jacobian,
            margin=margin,
            backend=b,
            chunk=chunk,
            progress=progress,
            couple23=self.chain.couple23,
        )

    def __repr__(self) -> str:
        K = "unknown" if self.stiffness is None else np.array2string(self.stiffness, precision=3)
        return f"RobotModel({self.name!r}, stiffness={K})"


def _check_wrench(wrench: ArrayLike, n: int, field: str = "wrench") -> F64:
    W = np.asarray(wrench, dtype=float)
    if W.shape == (6,):  # one wrench for every pose: checked once, then broadcast
        if not np.isfinite(W).all():
            raise InputError("wrench contains NaN or inf", field=field)
        return np.broadcast_to(W, (n, 6))
    if W.shape != (n, 6):
        raise InputError(f"expected wrenches of shape ({n}, 6) [f; m], got {W.shape}", field=field)
    if not np.all(np.isfinite(W)):
        raise InputError("wrench contains NaN or inf", field=field)
    return W


def _placement(T_base_work: ArrayLike) -> F64:
    T = np.asarray(T_base_work, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError(f"expected a finite (4, 4) transform, got {T.shape}", field="T_base_work")
    check_rigid(T, "T_base_work")
    return T
