"""Message authentication of what mpgspec stores and reads back (cached results, compiled chunks,
reports), so that a file edited or replaced outside mpgspec is never taken for its own work.

The key never lives in the cache folder (CI systems restore caches across branches, so a pull
request could otherwise write entries the main branch trusts): it is MPGSPEC_CACHE_KEY when set,
else a random per-machine key created once in the user's configuration folder
($XDG_CONFIG_HOME/mpgspec/cache.key, else ~/.config/mpgspec/cache.key, readable by its owner only),
or, where that folder cannot be written, in a folder of the temporary directory private to the
user. Where neither works, the key is random per process: nothing stored by another process
verifies, so everything is recomputed (correct, only slower), with one warning.
"""
from __future__ import annotations

import hashlib
import hmac
import json
import os
import tempfile
import warnings
from functools import lru_cache
from pathlib import Path

KEY_ENV = "MPGSPEC_CACHE_KEY"
KEY_BYTES = 32


def key_file() -> Path:
    """Where the per-machine key is kept (outside every cache folder)."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "mpgspec" / "cache.key"


@lru_cache(maxsize=None)
def _key(given: str | None, _config: str | None, _home: str | None) -> bytes:
    """key() for one setting of the variables it depends on (found once per setting, not once per
    stored row): MPGSPEC_CACHE_KEY hashed, else the key file, else one in this user's private
    folder of the temporary directory (a read-only home), else a random key for this process."""
    if given:
        return hashlib.sha256(given.encode("utf-8")).digest()
    path = key_file()
    fallback = Path(tempfile.gettempdir()) / f"mpgspec-{os.getuid() if hasattr(os, 'getuid') else 0}" / "cache.key"
    errors = []
    for p in (path, fallback):
        try:
            return _read_or_create(p, private=p == fallback)
        except (OSError, ValueError) as e:
            errors.append(f"{p}: {e}")
    warnings.warn(f"no usable cache key ({'; '.join(errors)}); set {KEY_ENV}: this run trusts nothing stored "
                  "before it")
    return os.urandom(KEY_BYTES)


def _read_or_create(p: Path, private: bool = False) -> bytes:
    """The key in file p, created (mode 600, atomically across processes) when missing; with
    `private`, its folder must be this user's alone."""
    if not p.is_file():
        p.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=".cache.key.")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(os.urandom(KEY_BYTES).hex().encode())
            os.chmod(tmp, 0o600)
            os.link(tmp, p)  # fails when another process created it first: then its key is read
        except FileExistsError:
            pass
        finally:
            os.unlink(tmp)
    if private:
        st = p.parent.stat()
        if hasattr(os, "getuid") and (st.st_uid != os.getuid() or st.st_mode & 0o077):
            raise ValueError("the folder is not private to this user")
    key = bytes.fromhex(p.read_text(encoding="ascii").strip())
    if len(key) < 16:
        raise ValueError("the key is too short")
    return key


def key() -> bytes:
    """The key of this machine or user (MPGSPEC_CACHE_KEY, else the key file)."""
    env = os.environ
    return _key(env.get(KEY_ENV) or None, env.get("XDG_CONFIG_HOME"), env.get("HOME"))


def mac(*parts: str | bytes) -> str:
    """HMAC-SHA256 (hex) of the parts, each length-prefixed so that no two part lists collide."""
    h = hmac.new(key(), digestmod=hashlib.sha256)
    for p in parts:
        b = p if isinstance(p, bytes) else str(p).encode("utf-8")
        h.update(len(b).to_bytes(8, "big"))
        h.update(b)
    return h.hexdigest()


def authentic(tag, *parts: str | bytes) -> bool:
    """Whether tag is mac(*parts) (compared in constant time; any non-string tag is not)."""
    return isinstance(tag, str) and hmac.compare_digest(tag, mac(*parts))


def file_mac(path: Path) -> str:
    """mac of a file's name and content."""
    return mac(Path(path).name, hashlib.sha256(Path(path).read_bytes()).digest())


def file_authentic(tag, path: Path) -> bool:
    """Whether tag is file_mac(path) (constant time)."""
    return isinstance(tag, str) and hmac.compare_digest(tag, file_mac(path))


def canonical(obj) -> bytes:
    """The JSON text a content hash is taken over: sorted keys, no whitespace, NaN as in Python."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode("ascii")


def content_hash(obj) -> str:
    """sha256 (hex) of canonical(obj)."""
    return hashlib.sha256(canonical(obj)).hexdigest()
