from .addon import register, unregister  # noqa: F401
__all__ = ["register", "unregister"]
