within Duffid;
package Examples "Example plants with declared inputs and outputs (exported as FMUs)"

  model Oscillator1DOF "One-DOF Duffing oscillator m*x'' + b*x' + k*x + kp*x^3 = f"
    input Units.Force f "Force on the mass";
    output Units.Position x "Displacement of the mass";
    output Units.Velocity v "Velocity of the mass";
    parameter Units.Mass m = 2.53 "Mass";
    parameter Units.TranslationalDampingConstant b = 12.47 "Viscous damping";
    parameter Units.TranslationalSpringConstant k = 1272.1 "Linear stiffness";
    parameter Units.CubicSpringConstant kp = -1.237e6 "Cubic stiffness (softening)";
    Translational.Fixed wall "Wall";
    Translational.CubicSpring spring(c = k, cp = kp) "Duffing spring";
    Translational.Damper damper(d = b) "Damper";
    Translational.Mass mass(m = m) "Mass";
    Translational.Force force "Applied force";
  equation
    connect(wall.flange, spring.flange_a);
    connect(wall.flange, damper.flange_a);
    connect(spring.flange_b, mass.flange_a);
    connect(damper.flange_b, mass.flange_a);
    connect(force.flange, mass.flange_b);
    force.f = f;
    x = mass.s;
    v = mass.v;
    annotation (experiment(StartTime = 0, StopTime = 2, Tolerance = 1e-8, Interval = 1e-3),
      Documentation(info = "<html><p>Paper Table 1 (b = 12.47 N s/m).</p></html>"));
  end Oscillator1DOF;

  model Oscillator1DOFPayload "Oscillator1DOF carrying a payload whose mass is an input (a plant that changes)"
    extends Oscillator1DOF;
    input Units.Mass payload "Mass of the payload carried by the mass (0: none); it moves with the mass";
    Translational.Force inertia "Inertial force of the payload";
  equation
    connect(inertia.flange, mass.flange_b);
    inertia.f = -payload*mass.a;
    annotation (experiment(StartTime = 0, StopTime = 2, Tolerance = 1e-8, Interval = 1e-3),
      Documentation(info = "<html><p>(m + payload) x'' + b x' + k x + kp x^3 = f: a step of the input
adds a payload at rest relative to the mass (position and velocity continuous).</p></html>"));
  end Oscillator1DOFPayload;

  model Oscillator2DOF "Two-DOF chain wall-m1-m2 (Figure 9, eqs. 20-21), force on m1"
    input Units.Force f1 "Force on mass 1";
    output Units.Position x1 "Displacement of mass 1";
    output Units.Position x2 "Displacement of mass 2";
    output Units.Velocity v1 "Velocity of mass 1";
    output Units.Velocity v2 "Velocity of mass 2";
    parameter Units.Mass m1 = 2.53 "Mass 1";
    parameter Units.TranslationalDampingConstant b1 = 5 "Damping wall-m1";
    parameter Units.TranslationalSpringConstant k1 = 1272.1 "Linear stiffness wall-m1";
    parameter Units.CubicSpringConstant kp1 = -1.237e6 "Cubic stiffness wall-m1";
    parameter Units.Mass m2 = 2.754 "Mass 2";
    parameter Units.TranslationalDampingConstant b2 = 4 "Damping m1-m2";
    parameter Units.TranslationalSpringConstant k2 = 1570 "Linear stiffness m1-m2";
    parameter Units.CubicSpringConstant kp2 = -1.35e6 "Cubic stiffness m1-m2";
    Translational.Fixed wall "Wall";
    Translational.CubicSpring spring1(c = k1, cp = kp1) "Spring wall-m1";
    Translational.Damper damper1(d = b1) "Damper wall-m1";
    Translational.Mass mass1(m = m1) "Mass 1";
    Translational.CubicSpring spring2(c = k2, cp = kp2) "Spring m1-m2";
    Translational.Damper damper2(d = b2) "Damper m1-m2";
    Translational.Mass mass2(m = m2) "Mass 2";
    Translational.Force force "Force on mass 1";
  equation
    connect(wall.flange, spring1.flange_a);
    connect(wall.flange, damper1.flange_a);
    connect(spring1.flange_b, mass1.flange_a);
    connect(damper1.flange_b, mass1.flange_a);
    connect(mass1.flange_b, spring2.flange_a);
    connect(mass1.flange_b, damper2.flange_a);
    connect(spring2.flange_b, mass2.flange_a);
    connect(damper2.flange_b, mass2.flange_a);
    connect(force.flange, mass1.flange_b);
    force.f = f1;
    x1 = mass1.s;
    x2 = mass2.s;
    v1 = mass1.v;
    v2 = mass2.v;
    annotation (experiment(StartTime = 0, StopTime = 2, Tolerance = 1e-8, Interval = 1e-3));
  end Oscillator2DOF;

  model ChainNDOF "Chain of n masses from a wall, Duffing elements and Coulomb friction, force on mass 1"
    parameter Integer n(min = 1) = 3 "Number of masses";
    input Units.Force f "Force on mass 1";
    output Units.Position x[n] "Displacements";
    output Units.Velocity v[n] "Velocities";
    parameter Units.Mass m[n] = fill(1, n) "Masses";
    parameter Units.TranslationalDampingConstant b[n] = fill(1, n) "Damping of element i (mass i-1 to i)";
    parameter Units.TranslationalSpringConstant k[n] = fill(1000, n) "Linear stiffness of element i";
    parameter Units.CubicSpringConstant kp[n] = fill(0, n) "Cubic stiffness of element i";
    parameter Units.Force fc[n] = fill(0, n) "Coulomb friction of mass i";
    Translational.Fixed wall "Wall";
    Translational.CubicSpring spring[n](c = k, cp = kp) "Springs";
    Translational.Damper damper[n](d = b) "Dampers";
    Translational.Mass mass[n](m = m) "Masses";
    Translational.CoulombFriction friction[n](fc = fc) "Friction of each mass on the ground";
    Translational.Force force "Force on mass 1";
  equation
    connect(wall.flange, spring[1].flange_a);
    connect(wall.flange, damper[1].flange_a);
    for i in 1:n loop
      connect(spring[i].flange_b, mass[i].flange_a);
      connect(damper[i].flange_b, mass[i].flange_a);
      connect(friction[i].flange, mass[i].flange_a);
      x[i] = mass[i].s;
      v[i] = mass[i].v;
    end for;
    for i in 2:n loop
      connect(mass[i - 1].flange_b, spring[i].flange_a);
      connect(mass[i - 1].flange_b, damper[i].flange_a);
    end for;
    connect(force.flange, mass[1].flange_b);
    force.f = f;
    annotation (experiment(StartTime = 0, StopTime = 2, Tolerance = 1e-8, Interval = 1e-3),
      Documentation(info = "<html><p>Element i joins mass i-1 (the wall for i = 1) to mass i
(<code>duffid.models.chain.Chain</code>, the defaults of its <code>model_from_name(&quot;chain&quot;)</code>).
The number of masses is structural: <code>duffid.modelica.export.export_fmu(...,
structural_parameters={&quot;n&quot;: 5})</code> exports a 5-mass chain.</p></html>"));
  end ChainNDOF;

  model DuffingCircuit "Series R-L-cubic capacitor: L*q'' + R*q' + q/C + a*q^3 = u"
    input Units.Voltage u "Source voltage";
    output Units.Charge q "Charge of the capacitor";
    output Units.Current i "Loop current";
    parameter Units.Inductance L = 0.1 "Inductance";
    parameter Units.Resistance R = 2 "Resistance";
    parameter Units.Capacitance C = 1e-3 "Small-signal capacitance";
    parameter Units.CubicElastance a = 5e6 "Cubic coefficient of the capacitor";
    Electrical.VoltageSource source "Voltage source";
    Electrical.Resistor resistor(R = R) "Resistor";
    Electrical.Inductor inductor(L = L) "Inductor";
    Electrical.CubicCapacitor capacitor(C = C, a = a) "Cubic capacitor";
    Electrical.Ground ground "Ground";
  equation
    connect(source.p, resistor.p);
    connect(resistor.n, inductor.p);
    connect(inductor.n, capacitor.p);
    connect(capacitor.n, source.n);
    connect(source.n, ground.p);
    source.u = u;
    q = capacitor.q;
    i = inductor.i;
    annotation (experiment(StartTime = 0, StopTime = 1, Tolerance = 1e-8, Interval = 1e-3));
  end DuffingCircuit;

  model SaturatingCircuit "Series R-saturating L-C circuit (nonlinear algebraic loop)"
    input Units.Voltage u "Source voltage";
    output Units.Current i "Loop current";
    output Units.Voltage vC "Capacitor voltage";
    output Units.MagneticFlux psi "Flux linkage of the inductor";
    parameter Units.Resistance R = 2 "Resistance";
    parameter Units.Inductance L0 = 0.1 "Inductance at zero current";
    parameter Units.Inductance Linf = 0.01 "Inductance in deep saturation";
    parameter Units.Current Isat = 1 "Current scale of the saturation";
    parameter Units.Capacitance C = 1e-3 "Capacitance";
    Electrical.VoltageSource source "Voltage source";
    Electrical.Resistor resistor(R = R) "Resistor";
    Electrical.SaturatingInductor inductor(L0 = L0, Linf = Linf, Isat = Isat) "Saturating inductor";
    Electrical.Capacitor capacitor(C = C) "Capacitor";
    Electrical.Ground ground "Ground";
  equation
    connect(source.p, resistor.p);
    connect(resistor.n, inductor.p);
    connect(inductor.n, capacitor.p);
    connect(capacitor.n, source.n);
    connect(source.n, ground.p);
    source.u = u;
    i = inductor.i;
    vC = capacitor.v;
    psi = inductor.psi;
    annotation (experiment(StartTime = 0, StopTime = 1, Tolerance = 1e-8, Interval = 1e-3));
  end SaturatingCircuit;
end Examples;
