"""Shared helpers for the rostest nodes in this folder (imported by the executable test scripts)."""
import json
import subprocess
import time

import yaml


def rosservice_call(service, yaml_request, timeout=30.0):
    """Call a service through the real ``rosservice call`` command line; returns the parsed YAML reply."""
    done = subprocess.run(["rosservice", "call", service, yaml_request], capture_output=True, text=True,
                          timeout=timeout)
    if done.returncode != 0:
        raise AssertionError("rosservice call %s failed (%d): %s %s" % (service, done.returncode, done.stdout,
                                                                         done.stderr))
    return yaml.safe_load(done.stdout)


def wait_until(predicate, timeout=5.0, period=0.02):
    """The first truthy value of ``predicate()`` (polled every ``period`` s), or its last value after ``timeout``."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(period)
    return predicate()


def result_of(text):
    value = json.loads(text)
    assert isinstance(value, dict), "result must be a JSON object, got %r" % text
    return value
