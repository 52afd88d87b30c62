within Duffid;
package Translational "1-D translational mechanics: flanges, masses, springs, dampers, friction"

  connector Flange "Translational flange: absolute position and cut force"
    Units.Position s "Absolute position of the flange";
    flow Units.Force f "Cut force directed into the flange";
  end Flange;

  model Fixed "Flange fixed at a constant position"
    parameter Units.Position s0 = 0 "Position of the fixed flange";
    Flange flange "Fixed flange";
  equation
    flange.s = s0;
  end Fixed;

  partial model PartialCompliant "Compliant connection of two flanges (force f from a to b)"
    Flange flange_a "Left flange";
    Flange flange_b "Right flange";
    Units.Position s_rel(start = 0) "Relative position (flange_b.s - flange_a.s)";
    Units.Force f "Force acting on flange_b (and -f on flange_a)";
  equation
    s_rel = flange_b.s - flange_a.s;
    flange_b.f = f;
    flange_a.f = -f;
  end PartialCompliant;

  model LinearSpring "Linear spring f = c*s_rel"
    extends PartialCompliant;
    parameter Units.TranslationalSpringConstant c(min = 0) = 1000 "Spring constant";
  equation
    f = c*s_rel;
  end LinearSpring;

  model PolynomialSpring "Polynomial spring f = sum(k[j]*s_rel^j, j = 1..r)"
    extends PartialCompliant;
    parameter Integer r(min = 1) = 3 "Order of the polynomial";
    parameter Real k[r] = {1000, 0, -1e6} "Coefficient of s_rel^j (unit N/m^j)";
    Real f_j[r](each unit = "N") "Force of each order j";
  equation
    for j in 1:r loop
      f_j[j] = k[j]*s_rel^j;
    end for;
    f = sum(f_j);
  end PolynomialSpring;

  model CubicSpring "Duffing spring f = c*s_rel + cp*s_rel^3 (PolynomialSpring of order 3)"
    extends PolynomialSpring(final r = 3, final k = {c, 0, cp});
    parameter Units.TranslationalSpringConstant c = 1000 "Linear spring constant";
    parameter Units.CubicSpringConstant cp = 0 "Cubic spring constant (negative: softening)";
  end CubicSpring;

  model Damper "Linear damper f = d*v_rel"
    extends PartialCompliant;
    parameter Units.TranslationalDampingConstant d(min = 0) = 1 "Damping constant";
    Units.Velocity v_rel "Relative velocity (der(s_rel))";
  equation
    v_rel = der(s_rel);
    f = d*v_rel;
  end Damper;

  model Mass "Sliding mass m*a = sum of the flange forces"
    parameter Units.Mass m(min = 0) = 1 "Mass";
    Flange flange_a "Left flange";
    Flange flange_b "Right flange";
    Units.Position s(start = 0, fixed = true) "Absolute position";
    Units.Velocity v(start = 0, fixed = true) "Absolute velocity";
    Units.Acceleration a "Absolute acceleration";
  equation
    flange_a.s = s;
    flange_b.s = s;
    v = der(s);
    a = der(v);
    m*a = flange_a.f + flange_b.f;
  end Mass;

  model CoulombFriction "Coulomb friction against the ground, smoothed: f = fc*tanh(v/v_smooth)"
    parameter Units.Force fc(min = 0) = 0 "Coulomb friction force";
    parameter Units.Velocity v_smooth(min = 0) = 1e-4 "Velocity where tanh reaches 0.76 fc";
    Flange flange "Flange rubbing on the ground";
    Units.Position s(start = 0) "Position of the flange";
    Units.Velocity v "Velocity of the flange";
  equation
    s = flange.s;
    v = der(s);
    flange.f = fc*tanh(v/v_smooth);
    annotation (Documentation(info = "<html>
<p>The sign function of ideal Coulomb friction is replaced by
<code>fc*tanh(v/v_smooth)</code> (default <code>v_smooth</code> = 1e-4 m/s, the law of
<code>duffid.models.chain.Chain</code>): a continuous law without events or stuck phases, so
that an ODE solver can integrate it (stiff for small <code>v_smooth</code>).</p></html>"));
  end CoulombFriction;

  model Force "Force from an input signal acting on a flange"
    input Units.Force f "Driving force (positive in the direction of the flange's position)";
    Flange flange "Driven flange";
  equation
    flange.f = -f;
  end Force;

  annotation (Documentation(info = "<html>
<p>Sign conventions as in <code>Modelica.Mechanics.Translational</code>: a flange carries
its absolute position <code>s</code> and the cut force <code>f</code> directed into the
component; compliant elements between <code>flange_a</code> and <code>flange_b</code>
carry the force <code>f</code> as a function of <code>s_rel = flange_b.s - flange_a.s</code>.
</p></html>"));
end Translational;
