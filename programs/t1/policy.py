"""The T1 locomotion policy of rcssservermj's example client, in numpy.

The example ships a GRU policy as a torch state_dict (`locomotion_nn.pth`,
a zip of a pickle and raw float32 storages) with its layout in
`locomotion_nn_meta.json`. This module reads the state_dict without torch,
through an unpickler that accepts exactly the four names such a file uses
(a tensor's rebuild, the float storage type, an ordered dict) and nothing
else, and runs the policy's forward pass: two observation encoders (dense,
layer norm, ELU), a GRU cell, and a torso of three dense layers to the
action mean.
"""

import io
import json
import pickle
import zipfile

import numpy as np


class _Storage:
    """A float32 storage of the archive, by key."""

    def __init__(self, data):
        self.data = data


def _rebuild_tensor(storage, offset, size, stride, *_):
    flat = storage.data
    if not size:
        return np.array(flat[offset], dtype=np.float32)
    return np.lib.stride_tricks.as_strided(
        flat[offset:], shape=tuple(size), strides=tuple(s * 4 for s in stride)
    ).copy()


class _FloatStorage:
    """Stands for torch.FloatStorage in a persistent id."""


class _Unpickler(pickle.Unpickler):
    ALLOWED = {
        ("torch._utils", "_rebuild_tensor_v2"): _rebuild_tensor,
        ("torch", "FloatStorage"): _FloatStorage,
        ("collections", "OrderedDict"): dict,
    }

    def __init__(self, data, storages):
        super().__init__(io.BytesIO(data))
        self._storages = storages

    def find_class(self, module, name):
        try:
            return self.ALLOWED[(module, name)]
        except KeyError:
            raise pickle.UnpicklingError(
                f"{module}.{name} is not part of a float32 state_dict"
            ) from None

    def persistent_load(self, pid):
        if not (isinstance(pid, tuple) and len(pid) == 5 and pid[0] == "storage"):
            raise pickle.UnpicklingError(f"unexpected persistent id {pid!r}")
        _, kind, key, _location, numel = pid
        if kind is not _FloatStorage:
            raise pickle.UnpicklingError("only float32 storages are read")
        data = self._storages(str(key))
        if data.size != numel:
            raise pickle.UnpicklingError(f"storage {key}: {data.size} floats, expected {numel}")
        return _Storage(data)


def read_state_dict(path):
    """A torch state_dict of float32 tensors, as name -> numpy array."""
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        pkl = [n for n in names if n.endswith("/data.pkl")]
        if len(pkl) != 1:
            raise ValueError(f"{path}: not a torch state_dict archive")
        root = pkl[0][: -len("data.pkl")]
        order = z.read(root + "byteorder").decode().strip() if root + "byteorder" in names else "little"
        dtype = np.dtype("<f4" if order == "little" else ">f4")

        def storage(key):
            return np.frombuffer(z.read(f"{root}data/{key}"), dtype=dtype).astype(np.float32)

        state = _Unpickler(z.read(pkl[0]), storage).load()
    if not isinstance(state, dict) or not all(isinstance(v, np.ndarray) for v in state.values()):
        raise ValueError(f"{path}: not a state_dict of tensors")
    return state


def _dense(p, name, x):
    return x @ p[name + ".weight"].T + p[name + ".bias"]


def _layer_norm(p, name, x, eps=1e-6):
    mean = x.mean(axis=-1, keepdims=True)
    var = ((x - mean) ** 2).mean(axis=-1, keepdims=True)
    return (x - mean) / np.sqrt(var + eps) * p[name + ".weight"] + p[name + ".bias"]


def _elu(x):
    return np.where(x > 0, x, np.expm1(np.minimum(x, 0)))


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


class Policy:
    """The GRU policy: `step(observation, hidden)` gives (action mean, hidden)."""

    def __init__(self, weights_path, meta_path):
        with open(meta_path, encoding="utf-8") as f:
            self.meta = json.load(f)
        if self.meta.get("gru_obs_combine_method") != "concat" or self.meta.get("share_gru_obs_encoder"):
            raise ValueError("only the example's layout (concat, separate encoders) is read")
        self.p = read_state_dict(weights_path)
        self.indices = np.asarray(self.meta["policy_observation_indices"], dtype=np.int64)
        self.hidden_dim = int(self.meta["gru_hidden_dim"])
        self.action_dim = int(self.meta["action_dim"])
        w = self.p["gru_obs_encoder_dense.weight"]
        if w.shape != (int(self.meta["obs_encoding_dim"]), self.indices.size):
            raise ValueError(f"encoder weight {w.shape} does not fit the meta")
        if self.p["mean_head.weight"].shape[0] != self.action_dim:
            raise ValueError("the action head does not fit the meta")

    def initial_hidden(self):
        return np.zeros(self.hidden_dim, dtype=np.float32)

    def step(self, observation, hidden):
        p = self.p
        x = np.asarray(observation, dtype=np.float32)[self.indices]
        gru_in = _elu(_layer_norm(p, "gru_obs_encoder_ln", _dense(p, "gru_obs_encoder_dense", x)))
        r = _sigmoid(_dense(p, "gru.ir", gru_in) + hidden @ p["gru.hr.weight"].T)
        z = _sigmoid(_dense(p, "gru.iz", gru_in) + hidden @ p["gru.hz.weight"].T)
        n = np.tanh(_dense(p, "gru.in_proj", gru_in) + r * _dense(p, "gru.hn", hidden))
        new_hidden = ((1.0 - z) * n + z * hidden).astype(np.float32)
        obs_latent = _elu(_layer_norm(p, "obs_encoder_ln", _dense(p, "obs_encoder_dense", x)))
        gru_latent = _elu(_layer_norm(p, "gru_ln", new_hidden))
        h = np.concatenate([obs_latent, gru_latent])
        h = _elu(_layer_norm(p, "torso_ln1", _dense(p, "torso_dense1", h)))
        h = _elu(_dense(p, "torso_dense2", h))
        h = _elu(_dense(p, "torso_dense3", h))
        return _dense(p, "mean_head", h).astype(np.float32), new_hidden
