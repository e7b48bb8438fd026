"""Gymnasium environments for bucket loading on the FEE force simulator.

``import wheelloader.envs`` registers:

* ``wheelloader/BucketLoading-v0``: one digging cycle, hidden soil "gravel",
  600 steps (10 s at 60 Hz); batched with ``gym.make_vec`` (NumPy vector env).
* ``wheelloader/BucketLoadingRandomSoil-v0``: as above, hidden soil drawn
  uniformly from the presets at every reset (domain randomisation).
* ``wheelloader/BucketLoadingBeyondModel-v0``: as above with truth beyond the
  model (compaction, rate-dependent resistance, stones).
* ``wheelloader/BucketLoadingMultiCycle-v0``: five cycles per episode on the
  same pile (carved surface kept and relaxed to the friction angle, soil
  drift between cycles), 3000 steps.

Keyword arguments of :class:`BucketLoadingEnv` pass through ``gym.make``.

Modules: ``bucket_loading`` (the env), ``vector`` (the NumPy-batched env; ``vector_api``
its Gymnasium vector API, ``batched_records`` its cycle records),
``bookkeeping`` (work, reward terms, cycle end and reset options, one copy
for every backend), ``config`` (``EnvConfig``, the settings, and the shared
random draws), ``rllib_env_config`` (construction from RLlib's ``env_config``
mapping), ``soils`` (hidden soil, domain randomisation), ``truth`` (effects
beyond the model), ``cycle_history`` (the finished cycles an env keeps),
``batched_surface``, ``scripted`` (path tracking), ``rendering``, and
``sb3`` (the stable-baselines3 adapter; import it only with
stable-baselines3 installed).
"""

from gymnasium.envs.registration import register, registry

from .bucket_loading import BucketLoadingEnv
from .config import REWARD_TERMS, EnvConfig, RewardTerms, RewardWeights, SoilRandomization
from .truth import TruthOptions

__all__ = ["ENV_IDS", "REWARD_TERMS", "BucketLoadingEnv", "BucketLoadingVectorEnv", "EnvConfig", "RewardTerms",
           "RewardWeights", "SoilRandomization", "TruthOptions"]

_ENTRY = "wheelloader.envs.bucket_loading:BucketLoadingEnv"
_VECTOR = "wheelloader.envs.vector:BucketLoadingVectorEnv"

#: Registered ids with their max_episode_steps, default kwargs and whether a batched vector env exists.
_SPECS: dict[str, tuple[int, dict, bool]] = {
    "wheelloader/BucketLoading-v0": (600, {}, True),
    "wheelloader/BucketLoadingRandomSoil-v0": (600, {"soil": "random"}, True),
    "wheelloader/BucketLoadingBeyondModel-v0": (
        600, {"truth": {"compaction": 0.5, "rate_resistance": 10_000.0, "stone_rate": 0.3}}, True),
    "wheelloader/BucketLoadingMultiCycle-v0": (
        3000, {"cycles_per_episode": 5, "relax": True, "truth": {"drift": 0.02}}, False),
}
#: The registered ids.
ENV_IDS: tuple[str, ...] = tuple(_SPECS)

for _id, (_steps, _kwargs, _vec) in _SPECS.items():
    if _id not in registry:
        register(id=_id, entry_point=_ENTRY, vector_entry_point=_VECTOR if _vec else None,
                 max_episode_steps=_steps, kwargs=_kwargs)


def __getattr__(name: str):
    if name == "BucketLoadingVectorEnv":
        from .vector import BucketLoadingVectorEnv

        return BucketLoadingVectorEnv
    raise AttributeError(name)
