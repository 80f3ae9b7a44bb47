"""The service tests' stand-in for systemd's notify socket."""

import pytest
from svc import NotifyListener


@pytest.fixture
def notify(tmp_path):
    n = NotifyListener(tmp_path / "notify")
    yield n
    n.close()
