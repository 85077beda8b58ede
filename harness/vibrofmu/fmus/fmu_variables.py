"""Description and unit of every FMU variable, written into modelDescription.xml after pythonfmu's build.

pythonfmu 0.7.0's variables take a description but no unit (pythonfmu/variables.py: Real has no `unit`
attribute), and the slaves register some variables without a description. `annotate` therefore
post-processes the built FMU: each variable without a description gets the one below, each Real variable
gets unit="1" (the model is dimensionless: time tau = omega_0 t, displacement x in units of the static
compression; "1" is FMI's name for a dimensionless unit), declared once in <UnitDefinitions>. A description
the slave gives is kept (it is the more specific one). Integer and Boolean variables have no unit in FMI 2.0.
"""
from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from pathlib import Path

from vibromodel.parameters import scene_descriptions

DIMENSIONLESS = "1"

# The scene's parameters are described where they are defined (vibromodel.parameters.Scene); the other variables:
DESCRIPTIONS = {
    "x": "displacement x (from the loaded equilibrium, in units of the static compression)",
    "v": "velocity x' = dx/dtau",
    "a": "acceleration x'' = d2x/dtau2",
    "F_contact": "Hertzian contact force (1 + 2x/3)^(3/2), 0 out of contact",
    "F_electrostatic": "electrostatic force (the alpha, beta and gamma terms)",
    "in_contact": "true while the contact is closed (1 + 2x/3 > 0)",
    "U": "control force U (added to the right-hand side of the equation of motion)",
    "x_ref": "reference displacement x~",
    "v_ref": "reference velocity x~'",
    "a_ref": "reference acceleration x~''",
    "e1": "tracking error e1 = x - x~",
    "e2": "filtered tracking error e2 = x' - x~' + c e1, c = sqrt(lambda1/lambda2)",
    "V": "Lyapunov function V = (lambda1 e1^2 + lambda2 e2^2 + sum of lambda_i theta~_i^2)/2",
    "V_rate": "dV/dtau of the run (chain rule)",
    "V_rate_promised": "dV/dtau the control law promises",
}


def description(name: str) -> str | None:
    """The description of variable `name` when its slave gives none (None: no entry)."""
    return DESCRIPTIONS.get(name, scene_descriptions().get(name))


def annotated_model_description(xml: bytes) -> bytes:
    """modelDescription.xml with every missing description filled in and unit="1" on every Real variable;
    raises ValueError naming a variable that has no description in the slave or in DESCRIPTIONS."""
    root = ET.fromstring(xml)
    for variable in root.iter("ScalarVariable"):
        name = variable.get("name")
        if not variable.get("description"):
            text = description(name)
            if text is None:
                raise ValueError(f"FMU variable {name} has no description (add it to {__name__}.DESCRIPTIONS, or to "
                                 "vibromodel.parameters.Scene for a scene parameter)")
            variable.set("description", text)
        real = variable.find("Real")
        if real is not None:
            real.set("unit", DIMENSIONLESS)
    units = root.find("UnitDefinitions")
    if units is None:
        units = ET.Element("UnitDefinitions")
        # FMI 2.0 schema order: ModelExchange?, CoSimulation?, UnitDefinitions?, TypeDefinitions?, ...
        after = [i for i, child in enumerate(root) if child.tag in ("ModelExchange", "CoSimulation")]
        root.insert(after[-1] + 1 if after else 0, units)
    if not any(unit.get("name") == DIMENSIONLESS for unit in units.iter("Unit")):
        ET.SubElement(units, "Unit", name=DIMENSIONLESS)
    ET.indent(root)
    out = io.BytesIO()
    ET.ElementTree(root).write(out, encoding="UTF-8", xml_declaration=True)
    return out.getvalue()


def annotate(fmu: Path) -> None:
    """Rewrite `fmu` in place with annotated_model_description; the other members are copied unchanged."""
    from vibrofmu.fmus.archive import rewrite_members

    rewrite_members(fmu, lambda name, data: annotated_model_description(data) if name == "modelDescription.xml"
                    else data)
