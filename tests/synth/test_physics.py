"""Ball flight physics: the RK4 integrator (inference.physics) and the event-driven flight with bounces,
net and walls (synth.physics), and the launch solver."""
from __future__ import annotations

import numpy as np
import pytest

from inference.court import Material, load_court
from inference.physics import FlightModel, integrate, rk4_step
from synth.physics import (
    bounce,
    free_flight,
    lower_to_net_height,
    simulate_flight,
    solve_launch,
)

REV = 2 * np.pi  # rad/s per rev/s


@pytest.fixture(scope="module")
def padel():
    return load_court("padel")


@pytest.fixture(scope="module")
def tennis():
    return load_court("tennis")


@pytest.fixture(scope="module")
def model(padel):
    return FlightModel.from_ball(padel.ball)


def landing(model, v0, spin=(0.0, 0.0, 0.0), p0=(0.0, 0.0, 1.0), radius=0.0328):
    """(2,) where a free flight comes down to z = r."""
    return free_flight(np.array(p0), np.array(v0, float), np.array(spin, float), model, radius, 1e9).landing


# ---------------------------------------------------------------------------------------------------
# inference.physics: forces and RK4


def test_vacuum_flight_is_the_analytic_parabola(model):
    p0, v0 = np.array([[1.0, 2.0, 1.0]]), np.array([[3.0, 20.0, 6.0]])
    fl = integrate(p0, v0, np.array([[0.0, -200.0, 50.0]]), 1.3, model.vacuum(), dt=1 / 600)
    t = fl.t[:, None]
    exact = p0 + v0 * t + 0.5 * np.array([0, 0, -model.gravity]) * t**2
    assert np.abs(fl.pos[:, 0] - exact).max() < 1e-9
    assert fl.t[-1] == pytest.approx(1.3)


def test_rk4_halving_the_step_changes_a_1s_flight_by_less_than_a_micrometre(model):
    p0, v0, w0 = np.array([0.0, 0.0, 1.0]), np.array([2.0, 30.0, 5.0]), np.array([-50 * REV, 0.0, 10 * REV])
    coarse = integrate(p0, v0, w0, 1.0, model, dt=1 / 600)
    fine = integrate(p0, v0, w0, 1.0, model, dt=1 / 1200, every=2)
    assert np.allclose(coarse.t, fine.t)
    assert np.abs(coarse.pos - fine.pos).max() < 1e-6
    # even a 20 ms step (the planner's look-ahead) is within a millimetre
    rough = integrate(p0, v0, w0, 1.0, model, dt=0.02)
    assert np.abs(rough.pos[-1] - coarse.pos[-1]).max() < 1e-3


def test_batch_equals_single_balls(model):
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 5, (6, 3))
    v = rng.uniform(-20, 20, (6, 3))
    w = rng.uniform(-300, 300, (6, 3))
    w[0] = 0.0  # no spin
    w[1] = v[1] * 5.0  # spin parallel to the velocity: no lift, no 0/0
    batch = integrate(p, v, w, 0.8, model)
    assert batch.pos.shape == (len(batch.t), 6, 3)
    for b in range(6):
        single = integrate(p[b], v[b], w[b], 0.8, model)
        assert np.allclose(single.pos[:, 0], batch.pos[:, b], rtol=0, atol=1e-12)
        assert np.allclose(single.vel[:, 0], batch.vel[:, b], rtol=0, atol=1e-12)
        assert np.allclose(single.spin[:, 0], batch.spin[:, b], rtol=0, atol=1e-12)
    assert np.all(np.isfinite(batch.pos))


def test_drag_slows_the_ball_and_shortens_the_range(model):
    v0 = np.array([0.0, 25.0, 6.0])
    air = integrate([0, 0, 1], v0, [0, 0, 0], 1.0, model)
    vac = integrate([0, 0, 1], v0, [0, 0, 0], 1.0, model.vacuum())
    assert np.linalg.norm(air.vel[-1, 0, :2]) < 0.9 * np.linalg.norm(vac.vel[-1, 0, :2])
    assert landing(model, v0)[1] < 0.85 * landing(model.vacuum(), v0)[1]
    # the drag acceleration is -k |v| v
    a = model.acceleration([[0.0, 20.0, 0.0]], [[0.0, 0.0, 0.0]])[0]
    assert a == pytest.approx([0.0, -model.drag_k * 400.0, -model.gravity])


def test_topspin_dips_and_backspin_floats(model):
    v0 = np.array([0.0, 20.0, 5.0])  # along +y: topspin turns about -x (ẑ × ŷ)
    flat = landing(model, v0)[1]
    top = landing(model, v0, spin=(-40 * REV, 0, 0))[1]
    back = landing(model, v0, spin=(40 * REV, 0, 0))[1]
    assert top < flat - 1.0 and back > flat + 1.0
    a_top = model.acceleration([v0], [[-40 * REV, 0, 0]])[0]
    a_flat = model.acceleration([v0], [[0, 0, 0]])[0]
    assert a_top[2] < a_flat[2] - 1.0  # Magnus pushes down


def test_sidespin_curves_the_ball_along_omega_cross_v(model):
    v0 = np.array([0.0, 20.0, 5.0])
    left = landing(model, v0, spin=(0, 0, 20 * REV))  # ω = +ẑ: ω × v ∝ ẑ × ŷ = -x̂
    right = landing(model, v0, spin=(0, 0, -20 * REV))
    assert left[0] < -0.3 and right[0] > 0.3
    assert left[0] == pytest.approx(-right[0], rel=1e-6)


def test_lift_coefficient_grows_with_spin_and_saturates(model):
    v = np.array([[0.0, 20.0, 0.0]])

    def lift(rev_s):
        a = model.acceleration(v, [[-rev_s * REV, 0, 0]])[0] - model.acceleration(v, [[0, 0, 0]])[0]
        return -a[2] / (model.lift_k * 400.0)  # C_L / C_L,max

    small, mid, huge = lift(1.0), lift(30.0), lift(3000.0)
    s_small = model.radius * REV / 20.0
    assert small == pytest.approx(s_small / (s_small + model.lift_half_spin), rel=1e-9)
    assert 0 < small < mid < huge < 1.0 and huge > 0.97
    # constant-C_L variant: the same force for any spin
    const = FlightModel.from_ball(load_court("padel").ball, lift_half_spin=0.0)
    a1 = const.acceleration(v, [[-1.0, 0, 0]])[0]
    a2 = const.acceleration(v, [[-500.0, 0, 0]])[0]
    assert a1 == pytest.approx(a2)


def test_spin_decays_with_the_documented_time_constant(model):
    fl = integrate([0, 0, 1], [0, 10, 5], [100.0, 0, 0], 1.0, model)
    assert fl.spin[-1, 0, 0] == pytest.approx(100.0 * np.exp(-1.0 / model.spin_decay_time), rel=1e-9)


def test_rk4_step_runs_on_floats_and_arrays(model):
    k = model.kernel()
    state = (0.0, 0.0, 1.0, 1.0, 20.0, 4.0, -100.0, 0.0, 20.0)
    one = rk4_step(state, 0.01, k)
    many = rk4_step(tuple(np.full(3, s) for s in state), 0.01, k)
    assert all(isinstance(x, float) for x in one)
    assert np.allclose(np.array(many).T, np.array(one), atol=1e-13)


def test_rk4_step_runs_on_torch_tensors_with_gradients(model):
    torch = pytest.importorskip("torch")
    v = torch.tensor([[1.0, 20.0, 5.0], [0.0, 12.0, 3.0]], dtype=torch.float64, requires_grad=True)
    zero = torch.zeros(2, dtype=torch.float64)
    state = (zero, zero, zero, *v.T, zero - 100.0, zero, zero + 30.0)
    for _ in range(60):
        state = rk4_step(state, 1 / 60, model.kernel())
    state[1].sum().backward()
    ref = integrate(np.zeros((2, 3)), v.detach().numpy(), [[-100.0, 0, 30.0]] * 2, 1.0, model, dt=1 / 60)
    assert np.allclose(state[1].detach().numpy(), ref.pos[-1, :, 1], atol=1e-12)
    eps = 1e-6
    bumped = integrate(np.zeros((2, 3)), v.detach().numpy() + [0, eps, 0], [[-100.0, 0, 30.0]] * 2, 1.0, model,
                       dt=1 / 60)
    fd = (bumped.pos[-1, :, 1] - ref.pos[-1, :, 1]) / eps
    assert np.allclose(v.grad[:, 1].numpy(), fd, rtol=1e-5)


# ---------------------------------------------------------------------------------------------------
# bounces


def rebound_heights(court, model, h0=2.0, n=3):
    fl = simulate_flight(court, np.array([5.0, 5.0, h0]), np.zeros(3), np.zeros(3), 0.0, 4.0, model=model,
                         max_ground=n + 1)
    t_bounce = [c.t for c in fl.contacts]
    r = court.ball.radius
    tops = [fl.pos[(fl.t > a) & (fl.t < b), 2].max() - r for a, b in zip(t_bounce, t_bounce[1:])]
    return [h0 - r, *tops]


def test_vertical_drop_rebounds_to_e_squared(padel, model):
    e2 = padel.materials["floor"].restitution ** 2
    vac = rebound_heights(padel, model.vacuum())
    ratios = np.array(vac[1:]) / np.array(vac[:-1])
    assert ratios == pytest.approx(e2, rel=1e-4)  # sampled maxima at 1/600 s
    air = rebound_heights(padel, model)
    ratios = np.array(air[1:]) / np.array(air[:-1])
    assert np.all((ratios > 0.92 * e2) & (ratios < e2))  # drag takes a little more


def test_bounce_slides_or_grips_per_coulomb_friction():
    n = np.array([0.0, 0.0, 1.0])
    r = 0.033
    # steep and fast along the surface, low friction: slides, tangential speed drops by μ(1+e)|v_n|
    mat = Material(restitution=0.7, friction=0.1)
    v, w = bounce(np.array([0.0, 20.0, -5.0]), np.zeros(3), n, mat, r)
    assert v[2] == pytest.approx(3.5)
    assert v[1] == pytest.approx(20.0 - 0.1 * 1.7 * 5.0)
    assert w[0] < 0  # friction at the bottom spins it forward (topspin about -x for motion along +y)
    # high friction: grips, leaves rolling (contact point at rest), v_t reduced to 1/(1+α) of its value
    mat = Material(restitution=0.7, friction=2.0)
    v, w = bounce(np.array([0.0, 10.0, -5.0]), np.zeros(3), n, mat, r)
    slip = v - r * np.cross(w, n)
    assert np.abs(slip[:2]).max() < 1e-9
    assert v[1] == pytest.approx(10.0 * 0.6)  # hollow sphere α = 2/3
    # backspin takes more forward speed away than topspin
    vt, _ = bounce(np.array([0.0, 15.0, -6.0]), np.array([-300.0, 0, 0]), n, Material(0.75, 0.6), r)
    vb, _ = bounce(np.array([0.0, 15.0, -6.0]), np.array([300.0, 0, 0]), n, Material(0.75, 0.6), r)
    assert vb[1] < vt[1]


def test_bounce_never_adds_energy():
    rng = np.random.default_rng(0)
    m_over_i = 1 / (2 / 3 * 0.033**2)  # kinetic energy per mass: v²/2 + I ω²/(2m)
    for _ in range(200):
        v = rng.normal(0, 10, 3)
        v[2] = -abs(v[2]) - 0.1
        w = rng.normal(0, 200, 3)
        mat = Material(rng.uniform(0.1, 0.9), rng.uniform(0.0, 1.0))
        v2, w2 = bounce(v, w, np.array([0, 0, 1.0]), mat, 0.033)
        before = v @ v + w @ w / m_over_i
        after = v2 @ v2 + w2 @ w2 / m_over_i
        assert after <= before + 1e-9


# ---------------------------------------------------------------------------------------------------
# contacts of simulated flights


def assert_on_planes(court, flight, tol=1e-3):
    r = court.ball.radius
    for c in flight.contacts:
        plane = court.plane(c.plane)
        assert c.event == plane.event
        d = abs(float((c.position - plane.origin) @ plane.normal))
        assert abs(d - r) < tol, (c, d)
        assert plane.contains(c.position[None])[0], c
        # the path goes through the contact
        k = np.searchsorted(flight.t, c.t)
        assert flight.t[k] == pytest.approx(c.t, abs=1e-12)
        assert np.allclose(flight.pos[k], c.position)


def test_padel_shot_bounces_then_comes_off_the_back_glass(padel):
    fl = simulate_flight(padel, np.array([3.0, 2.0, 1.0]), np.array([1.0, 15.0, 4.0]), np.zeros(3), 0.0, 2.5)
    events = [c.event for c in fl.contacts]
    assert events[:3] == ["ground", "wall_far", "ground"]
    assert_on_planes(padel, fl)
    k = np.searchsorted(fl.t, fl.contacts[1].t)
    v_in, v_out = fl.vel[k - 1], fl.vel[k]
    assert v_out[1] < 0 < v_in[1]
    assert -v_out[1] == pytest.approx(padel.materials["glass"].restitution * v_in[1], rel=0.02)
    assert np.all(np.diff(fl.t) > 0)


def test_contact_times_are_refined_below_a_tenth_of_a_millisecond(padel):
    p0, v0, w0 = np.array([3.0, 2.0, 1.0]), np.array([1.0, 15.0, 4.0]), np.array([-100.0, 0, 30.0])
    args = (padel, p0, v0, w0, 0.0, 2.0)
    a = simulate_flight(*args, dt=1 / 600)
    b = simulate_flight(*args, dt=1 / 2400)
    assert [c.event for c in a.contacts] == [c.event for c in b.contacts]
    for ca, cb in zip(a.contacts, b.contacts):
        assert abs(ca.t - cb.t) < 1e-4
        assert np.abs(ca.position - cb.position).max() < 1e-4
    floor = [c for c in a.contacts if c.event == "ground"]
    assert all(abs(c.position[2] - padel.ball.radius) < 1e-6 for c in floor)


def test_ball_into_the_net_drops_on_its_side(padel):
    fl = simulate_flight(padel, np.array([5.0, 5.0, 0.5]), np.array([0.0, 12.0, 1.5]), np.zeros(3), 0.0, 2.0)
    assert fl.contacts[0].event == "net"
    assert_on_planes(padel, fl)
    k = np.searchsorted(fl.t, fl.contacts[0].t)
    assert np.linalg.norm(fl.vel[k]) < 0.3 * np.linalg.norm(fl.vel[k - 1])  # lost most of its speed
    assert fl.contacts[1].event == "ground" and fl.contacts[1].position[1] < padel.net_y
    assert np.all(fl.pos[:, 1] < padel.net_y)


def test_ball_on_the_net_cord_trickles_over(tennis):
    # the centre reaches the net 1.5-3 cm below the tape (it falls 4 mm on the way)
    for dz in (0.01, 0.025):
        p0 = np.array([5.485, tennis.net_y - 0.3, 0.914 - dz])
        fl = simulate_flight(tennis, p0, np.array([0.0, 10.0, 0.0]), np.zeros(3), 0.0, 1.5)
        assert fl.contacts[0].event == "net"
        assert fl.pos[-1, 1] > tennis.net_y + 0.1  # it went over
        assert fl.contacts[1].event == "ground" and fl.contacts[1].position[1] > tennis.net_y


def test_mesh_contacts_are_labelled_mesh(padel):
    p0, v0 = np.array([5.0, 10.0, 2.5]), np.array([-12.0, 0.0, 1.0])
    fl = simulate_flight(padel, p0, v0, np.zeros(3), 0.0, 0.6)
    assert fl.contacts[0].event == "mesh" and fl.contacts[0].plane == "mesh_left"
    assert_on_planes(padel, fl)


def test_ball_over_the_back_mesh_leaves_the_court(padel):
    fl = simulate_flight(padel, np.array([5.0, 15.0, 5.0]), np.array([0.0, 8.0, 2.0]), np.zeros(3), 0.0, 3.0)
    assert fl.contacts == []
    assert fl.end == "left" and fl.pos[-1, 1] > 20.0


def test_settled_ball_rolls_without_more_contacts(padel):
    fl = simulate_flight(padel, np.array([5.0, 5.0, 0.3]), np.array([0.0, 2.0, 0.0]), np.zeros(3), 0.0, 6.0)
    assert fl.end == "rest"
    assert np.allclose(fl.pos[-50:, 2], padel.ball.radius)
    assert len(fl.contacts) < 15
    assert np.all(np.diff(fl.t) > 0)


def test_max_ground_stops_after_the_second_bounce(padel):
    fl = simulate_flight(padel, np.array([5.0, 3.0, 1.0]), np.array([0.0, 6.0, 3.0]), np.zeros(3), 0.0, 5.0,
                         max_ground=2)
    assert [c.event for c in fl.contacts].count("ground") == 2
    assert fl.end == "ground" and fl.t[-1] == pytest.approx(fl.contacts[-1].t)


# ---------------------------------------------------------------------------------------------------
# launch solving


@pytest.mark.parametrize("spin_rev", [-20.0, 0.0, 40.0])
def test_solved_launch_lands_on_target_and_clears_the_net_as_asked(tennis, spin_rev):
    model = FlightModel.from_ball(tennis.ball)
    p0, target = np.array([4.0, -0.5, 0.9]), np.array([7.0, 20.5])
    spin = np.array([-spin_rev * REV, 0.0, 5 * REV])
    sol = solve_launch(p0, spin, target, model, tennis.ball.radius, tennis.net_y, net_height=lambda x: 1.6)
    assert sol.ok and sol.flight.net_z == pytest.approx(1.6, abs=0.01)
    fl = simulate_flight(tennis, p0, sol.vel, spin, 0.0, 3.0, max_ground=1)
    assert np.linalg.norm(fl.contacts[0].position[:2] - target) < 0.02


def test_solved_serve_has_the_asked_speed(tennis):
    model = FlightModel.from_ball(tennis.ball)
    sol = solve_launch(np.array([6.0, -0.3, 2.85]), np.array([-100.0, 0, 50.0]), np.array([3.5, 17.0]), model,
                       tennis.ball.radius, tennis.net_y, speed=48.0)
    assert sol.ok and sol.speed == pytest.approx(48.0, abs=0.01)
    assert sol.flight.net_z > 0.914 + tennis.ball.radius


def test_lowered_launch_goes_into_the_net(padel):
    model = FlightModel.from_ball(padel.ball)
    p0, spin = np.array([4.0, 2.0, 1.0]), np.zeros(3)
    sol = solve_launch(p0, spin, np.array([6.0, 16.0]), model, padel.ball.radius, padel.net_y,
                       net_height=lambda x: 1.5)
    low = lower_to_net_height(p0, sol.vel, spin, model, padel.ball.radius, padel.net_y, 0.5)
    assert low.ok and low.speed == pytest.approx(sol.speed)
    fl = simulate_flight(padel, p0, low.vel, spin, 0.0, 2.0)
    assert fl.contacts[0].event == "net"
    assert fl.contacts[0].position[2] == pytest.approx(0.5, abs=0.02)


def test_the_compiled_flight_path_is_the_step_by_step_one(monkeypatch):
    """``rk4_path`` (the 3D fit's integrator, compiled with numba when installed) gives the positions and velocities
    of :func:`rk4_step` repeated, bit for bit, forwards and backwards, with one drag per ball; without numba the
    NumPy loop runs."""
    import inference.physics as ph

    rng = np.random.default_rng(4)
    B = 40
    state = tuple(rng.normal(size=B) * s for s in (3, 3, 1, 10, 10, 3, 30, 30, 30))
    h = np.where(rng.random(B) > 0.5, 1.0, -1.0) / 200.0
    c = list(ph.FlightModel.from_ball(load_court("padel").ball).kernel())
    c[1] = c[1] * (1 + 0.2 * rng.random(B))
    f = ph.spin_factors(h, c[5])
    P, V, last = ph.rk4_path(state, h, c, f, 25, 3)
    s = state
    for j in range(25):
        np.testing.assert_array_equal(P[j], np.stack(s[:3]))
        np.testing.assert_array_equal(V[j], np.stack(s[3:6]))
        if j < 24:
            for _ in range(3):
                s = ph.rk4_step(s, h, c, f)
    np.testing.assert_array_equal(np.stack(last), np.stack(s))
    assert ph.path_kernel() is not None, "numba is a dependency (pyproject.toml): the compiled kernel should load"
    monkeypatch.setattr(ph, "_path_kernel", None)   # no numba
    P2, V2, _ = ph.rk4_path(state, h, c, f, 25, 3)
    np.testing.assert_array_equal(P2, P)
    np.testing.assert_array_equal(V2, V)
