"""Checks programs/t1/policy.py's numpy forward pass against the policy's
equations written out in plain Python (lists and math, one number at a
time) on fixed inputs: five steps of a recurrent rollout. Usage:
python t1_policy_check.py PREFIX (a T1 set-up). Prints the largest
difference; exits 1 if it is above 1e-4."""
import math
import os
import random
import sys

prefix = sys.argv[1]
sys.path.insert(0, os.path.join(prefix, "bin"))
import policy  # noqa: E402

P = policy.Policy(os.path.join(prefix, "policy", "locomotion_nn.pth"),
                  os.path.join(prefix, "policy", "locomotion_nn_meta.json"))
W = {k: v.tolist() for k, v in P.p.items()}


def dense(name, x):
    w, b = W[name + ".weight"], W[name + ".bias"]
    return [sum(wi * xi for wi, xi in zip(row, x)) + bj for row, bj in zip(w, b)]


def matvec(name, x):
    return [sum(wi * xi for wi, xi in zip(row, x)) for row in W[name + ".weight"]]


def norm(name, x):
    m = sum(x) / len(x)
    v = sum((xi - m) ** 2 for xi in x) / len(x)
    return [(xi - m) / math.sqrt(v + 1e-6) * g + b
            for xi, g, b in zip(x, W[name + ".weight"], W[name + ".bias"])]


def elu(x):
    return [xi if xi > 0 else math.exp(xi) - 1.0 for xi in x]


def sig(x):
    return [1.0 / (1.0 + math.exp(-xi)) for xi in x]


def step(obs, h):
    x = [obs[i] for i in P.meta["policy_observation_indices"]]
    g = elu(norm("gru_obs_encoder_ln", dense("gru_obs_encoder_dense", x)))
    r = sig([a + b for a, b in zip(dense("gru.ir", g), matvec("gru.hr", h))])
    z = sig([a + b for a, b in zip(dense("gru.iz", g), matvec("gru.hz", h))])
    n = [math.tanh(a + ri * b) for a, ri, b in zip(dense("gru.in_proj", g), r, dense("gru.hn", h))]
    h2 = [(1 - zi) * ni + zi * hi for zi, ni, hi in zip(z, n, h)]
    o = elu(norm("obs_encoder_ln", dense("obs_encoder_dense", x)))
    t = o + elu(norm("gru_ln", h2))
    t = elu(norm("torso_ln1", dense("torso_dense1", t)))
    t = elu(dense("torso_dense2", t))
    t = elu(dense("torso_dense3", t))
    return dense("mean_head", t), h2


rng = random.Random(7)
h_np, h_py = P.initial_hidden(), [0.0] * P.hidden_dim
worst = 0.0
for _ in range(5):
    obs = [rng.uniform(-1.0, 1.0) for _ in range(82)]
    a_np, h_np = P.step(obs, h_np)
    a_py, h_py = step(obs, h_py)
    worst = max(worst, max(abs(a - b) for a, b in zip(a_np.tolist(), a_py)),
                max(abs(a - b) for a, b in zip(h_np.tolist(), h_py)))
    if max(abs(a) for a in a_py) == 0.0:
        sys.exit("the plain evaluation gave a zero action")
print(f"largest difference {worst:.3g}")
sys.exit(0 if worst < 1e-4 else 1)
