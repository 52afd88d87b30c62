within Duffid;
package Electrical "Analog circuits: pins, passive components (linear and nonlinear), voltage source"

  connector Pin "Electrical pin: potential and current"
    Units.Voltage v "Potential at the pin";
    flow Units.Current i "Current flowing into the pin";
  end Pin;

  model Ground "Ground node (potential 0)"
    Pin p "Grounded pin";
  equation
    p.v = 0;
  end Ground;

  partial model OnePort "Component with two pins and the current i from p to n"
    Pin p "Positive pin";
    Pin n "Negative pin";
    Units.Voltage v "Voltage drop p.v - n.v";
    Units.Current i "Current from p to n";
  equation
    v = p.v - n.v;
    0 = p.i + n.i;
    i = p.i;
  end OnePort;

  model Resistor "Linear resistor v = R*i"
    extends OnePort;
    parameter Units.Resistance R = 1 "Resistance";
  equation
    v = R*i;
  end Resistor;

  model Inductor "Linear inductor L*der(i) = v"
    extends OnePort(i(start = 0, fixed = true));
    parameter Units.Inductance L = 1 "Inductance";
  equation
    L*der(i) = v;
  end Inductor;

  model Capacitor "Linear capacitor C*der(v) = i"
    extends OnePort(v(start = 0, fixed = true));
    parameter Units.Capacitance C(min = 0) = 1e-3 "Capacitance";
  equation
    C*der(v) = i;
  end Capacitor;

  model CubicCapacitor "Nonlinear capacitor v = q/C + a*q^3"
    extends OnePort;
    parameter Units.Capacitance C(min = 0) = 1e-3 "Small-signal capacitance";
    parameter Units.CubicElastance a = 0 "Cubic coefficient";
    Units.Charge q(start = 0, fixed = true) "Charge";
  equation
    i = der(q);
    v = q/C + a*q^3;
  end CubicCapacitor;

  model SaturatingInductor "Inductor with a saturating flux linkage psi(i)"
    extends OnePort;
    parameter Units.Inductance L0(min = 0) = 0.1 "Inductance at zero current";
    parameter Units.Inductance Linf(min = 0) = 0.01 "Inductance in deep saturation";
    parameter Units.Current Isat(min = 0) = 1 "Current scale of the saturation";
    Units.MagneticFlux psi(start = 0, fixed = true) "Flux linkage";
  equation
    psi = Linf*i + (L0 - Linf)*Isat*tanh(i/Isat);
    v = der(psi);
    annotation (Documentation(info = "<html>
<p>The flux linkage is the state; the current follows from the implicit nonlinear
equation <code>psi = Linf*i + (L0 - Linf)*Isat*tanh(i/Isat)</code> (monotone in
<code>i</code> for <code>L0, Linf &gt; 0</code>), an algebraic loop solved by Newton's
method in the exported FMU.</p></html>"));
  end SaturatingInductor;

  model VoltageSource "Voltage source driven by an input signal"
    extends OnePort;
    input Units.Voltage u "Source voltage (p.v - n.v)";
  equation
    v = u;
  end VoltageSource;
end Electrical;
