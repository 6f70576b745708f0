"""``import sitgen.gym`` registers ``sitgen/Navigate-v0`` (the environments live in
:mod:`sitgen.controllers.gym`; this name is the one users import)."""

from sitgen.controllers.gym import NavigateEnv, NavigateVectorEnv

__all__ = ["NavigateEnv", "NavigateVectorEnv"]
