within Duffid;
package Units "SI types (quantity and unit) used by the library"
  type Position = Real(final quantity = "Length", final unit = "m") "Position";
  type Velocity = Real(final quantity = "Velocity", final unit = "m/s") "Velocity";
  type Acceleration = Real(final quantity = "Acceleration", final unit = "m/s2") "Acceleration";
  type Force = Real(final quantity = "Force", final unit = "N") "Force";
  type Mass = Real(final quantity = "Mass", final unit = "kg", min = 0) "Mass";
  type TranslationalSpringConstant = Real(final quantity = "TranslationalSpringConstant",
    final unit = "N/m") "Linear spring constant";
  type CubicSpringConstant = Real(final unit = "N/m3") "Cubic spring constant";
  type TranslationalDampingConstant = Real(final quantity = "TranslationalDampingConstant",
    final unit = "N.s/m") "Viscous damping constant";
  type Voltage = Real(final quantity = "ElectricPotential", final unit = "V") "Voltage";
  type Current = Real(final quantity = "ElectricCurrent", final unit = "A") "Current";
  type Charge = Real(final quantity = "ElectricCharge", final unit = "C") "Charge";
  type MagneticFlux = Real(final quantity = "MagneticFlux", final unit = "Wb") "Flux linkage";
  type Resistance = Real(final quantity = "Resistance", final unit = "Ohm") "Resistance";
  type Inductance = Real(final quantity = "Inductance", final unit = "H") "Inductance";
  type Capacitance = Real(final quantity = "Capacitance", final unit = "F", min = 0) "Capacitance";
  type CubicElastance = Real(final unit = "V/C3") "Cubic coefficient of a capacitor's voltage";
  annotation (Documentation(info = "<html>
<p>The subset of <code>Modelica.Units.SI</code> the library needs, defined here so that
the library loads without the Modelica Standard Library.</p></html>"));
end Units;
