"""Material tables (scene files) and the registry of material types."""

from dataclasses import dataclass

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import Dipole, Lambertian, measured_medium
from translucent.materials.factory import (
    MATERIAL_TYPES,
    material_from_dict,
    material_to_dict,
    register_material_type,
)
from translucent.scenes import loads_scene


def test_measured_dipole_and_lambertian_tables():
    marble = material_from_dict({"type": "measured", "name": "MARBLE"})
    assert marble.cache_key() == measured_medium("Marble").cache_key()
    assert marble.name == "Marble"
    dipole = material_from_dict({"type": "dipole", "sigma_a": [0.1, 0.2, 0.3],
                                 "sigma_s_prime": 1.5, "eta": 1.4, "g": 0.5})
    assert isinstance(dipole, Dipole)
    np.testing.assert_array_equal(dipole.sigma_s_prime, [1.5, 1.5, 1.5])
    assert (dipole.eta, dipole.g) == (1.4, 0.5)
    lambertian = material_from_dict({"type": "lambertian", "albedo": [0.2, 0.4, 0.6]})
    assert isinstance(lambertian, Lambertian)


@pytest.mark.parametrize("table", [
    {"type": "measured", "name": "Skin1"},
    {"type": "dipole", "sigma_a": [0.1, 0.2, 0.3], "sigma_s_prime": [1.0, 2.0, 3.0],
     "eta": 1.2, "g": -0.3, "name": "custom"},
    {"type": "lambertian", "albedo": [0.1, 0.5, 0.9]},
])
def test_material_to_dict_round_trips(table):
    material = material_from_dict(table)
    back = material_from_dict(material_to_dict(material))
    assert type(back) is type(material)
    assert back.cache_key() == material.cache_key() and back.name == material.name


def test_edited_measured_medium_is_written_as_a_dipole():
    edited = Dipole(sigma_a=measured_medium("Marble").sigma_a * 2,
                    sigma_s_prime=measured_medium("Marble").sigma_s_prime, eta=1.5,
                    name="Marble")
    assert material_to_dict(edited)["type"] == "dipole"


@pytest.mark.parametrize("table, match", [
    ({"type": "glass"}, r"m\.toml: objects\[1\]\.material\.type = 'glass': unknown material "
                        r"type; valid: .*dipole, .*lambertian, measured"),
    ({"name": "marble"}, r"objects\[1\]\.material\.type = None: unknown material type"),
    ({"type": "measured", "name": "marmite"},
     r"objects\[1\]\.material\.name = 'marmite': unknown measured material; valid names: "
     r"Apple, Chicken1"),
    ({"type": "dipole", "sigma_a": 0.1}, r"objects\[1\]\.material\.sigma_s_prime: a dipole "
                                         r"material needs sigma_s_prime"),
    ({"type": "dipole", "sigma_a": [0.1, float("nan"), 0.1], "sigma_s_prime": 1.0},
     r"objects\[1\]\.material\.sigma_a = .*0\.1, nan, 0\.1.*: must be finite"),
    ({"type": "dipole", "sigma_a": 0.1, "sigma_s_prime": -1.0},
     r"objects\[1\]\.material\.sigma_s_prime = -1\.0: must be >= 0"),
    ({"type": "dipole", "sigma_a": 0.1, "sigma_s_prime": 1.0, "eta": 5.0},
     r"objects\[1\]\.material\.eta = 5\.0: must be in \[1, 3\]"),
    ({"type": "lambertian", "albedo": 0.5, "roughness": 0.1},
     r"objects\[1\]\.material\.roughness = 0\.1: unknown key for a lambertian material; "
     r"valid keys: type, albedo, name"),
    ({"type": "lambertian", "albedo": [0.5, 0.5]},
     r"objects\[1\]\.material\.albedo = \[0\.5, 0\.5\]: must be a number or an RGB triple"),
    ("marble", r"objects\[1\]\.material = 'marble': must be a table"),
])
def test_bad_tables_name_file_field_and_value(table, match):
    with pytest.raises(InputError, match=match):
        material_from_dict(table, file="m.toml", field="objects[1].material")


@dataclass(frozen=True)
class Velvet:
    """A material type defined outside the factory."""

    sheen: float
    name: str = ""

    def __post_init__(self):
        if not 0 <= self.sheen <= 1:
            raise InputError("must be in [0, 1]", field="sheen", value=self.sheen)


@pytest.fixture
def velvet():
    register_material_type("velvet", Velvet)
    yield
    del MATERIAL_TYPES["velvet"]


def test_registered_type_is_usable_from_a_scene_file(velvet):
    scene = loads_scene("""
        [camera]
        origin = [0.0, 0.0, 3.0]
        target = [0.0, 0.0, 0.0]
        [[objects]]
        name = "cushion"
        mesh = { type = "box" }
        material = { type = "velvet", sheen = 0.25 }
        """.replace("\n        ", "\n"))
    assert scene.object("cushion").material == Velvet(0.25)
    assert material_to_dict(Velvet(0.5, "red")) == {"type": "velvet", "sheen": 0.5,
                                                    "name": "red"}
    with pytest.raises(InputError, match=r"material\.sheen = 2: must be in \[0, 1\]"):
        material_from_dict({"type": "velvet", "sheen": 2})
    with pytest.raises(InputError, match=r"valid keys: type, sheen, name"):
        material_from_dict({"type": "velvet", "sheen": 0.1, "pile": 3})


def test_registry_checks_names_and_unknown_classes():
    with pytest.raises(InputError, match=r"type = 'Velvet': .*lower-case"):
        register_material_type("Velvet", Velvet)
    with pytest.raises(InputError, match=r"material = 'object': no registered material type"):
        material_to_dict(object())


def test_measured_medium_with_its_index_replaced():
    from translucent.materials.factory import material_from_dict, material_to_dict

    matched = material_from_dict({"type": "measured", "name": "marble", "eta": 1.0})
    assert matched.eta == 1.0 and matched.sigma_a.tolist() == [0.0021, 0.0041, 0.0071]
    assert material_to_dict(matched) == {"type": "measured", "name": "Marble", "eta": 1.0}
    with pytest.raises(InputError, match=r"material\.eta = 0\.5: must be in \[1, 3\]"):
        material_from_dict({"type": "measured", "name": "marble", "eta": 0.5})
