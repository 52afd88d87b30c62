package CosimTest "Tiny models for the co-simulation tests"
  model Ramp "y = y0 + a*t"
    parameter Real a = 1 "Slope";
    parameter Real y0 = 0 "Initial value";
    Real s(start = 0, fixed = true) "a*t";
    output Real y "Ramp";
  equation
    der(s) = a;
    y = s + y0;
  end Ramp;
  model Integrator "y = y0 + integral of u"
    parameter Real y0 = 0 "Initial value";
    input Real u "Input";
    Real s(start = 0, fixed = true) "Integral of u";
    output Real y "y0 + integral of u";
  equation
    der(s) = u;
    y = s + y0;
  end Integrator;
  model Gain "y = k*u"
    parameter Real k = 2 "Gain";
    input Real u "Input";
    output Real y "Output";
  equation
    y = k*u;
  end Gain;
end CosimTest;
