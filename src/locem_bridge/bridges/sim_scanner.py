"""SCAN source for the simulated worksite: the perception stand-in (``locem_bridge.sim.perception``) run on the
site YAML from the robot's odometry pose. A real robot names another scanner backend in its YAML."""

from typing import Any, Dict, Mapping, Sequence

from .errors import BridgeConfigError
from .interfaces import Scanner


class SiteScanner(Scanner):
    """Visible wall features of the configured site (docs/contracts.md SCAN shape)."""

    def __init__(self, scanner_cfg: Mapping[str, Any], site: Any) -> None:
        """``site``: the site YAML path, or its already validated contents (``locem_bridge.sim.config``)."""
        from locem_bridge.common.config_errors import ConfigError
        from locem_bridge.sim.config import load_site
        from locem_bridge.sim.perception import WallScanner
        from locem_bridge.sim.site import Site

        if not site:
            raise BridgeConfigError("the sim scanner needs the site configuration (~site_config)")
        try:
            site_cfg = load_site(site) if isinstance(site, str) else site
        except ConfigError as error:          # one line: FILE: KEY: PROBLEM (allowed: ...)
            raise BridgeConfigError(error.problem, file=error.file or str(site), key=error.key,
                                    allowed=error.allowed or None)
        except Exception as error:
            raise BridgeConfigError("cannot be loaded: %s" % error, file=str(site))
        sim = dict(site_cfg.get("simulation", {}))
        noise = float(dict(sim.get("perception", {})).get("position_noise", 0.0))
        self._scanner = WallScanner(Site(dict(site_cfg)), dict(scanner_cfg), noise, int(sim.get("seed", 1)))

    def scan(self, base_pose: Sequence[float]) -> Dict[str, Any]:
        import time
        return self._scanner.scan(list(base_pose), stamp=time.time())
