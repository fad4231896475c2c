"""npz_io.write_npz: the file lands exactly where asked, whatever its suffix."""

from __future__ import annotations

import numpy as np
import pytest

from physpose.errors import PhysposeError
from physpose.npz_io import read_npz, write_npz


@pytest.mark.parametrize("name", ["recon.npz", "recon", "recon.data"])
def test_written_under_the_name_given(tmp_path, name):
    path = write_npz(tmp_path / name, {"a": np.arange(3)})
    assert path == tmp_path / name and sorted(p.name for p in tmp_path.iterdir()) == [name]
    np.testing.assert_array_equal(read_npz(path, what="test", remedy="-")["a"], np.arange(3))


def test_a_folder_is_refused_with_the_file_it_could_be(tmp_path):
    with pytest.raises(PhysposeError, match="this is a folder") as err:
        write_npz(tmp_path, {"a": np.arange(3)})
    assert "name.npz" in str(err.value)
