//! The case's `system` dictionaries: a potential-flow start that runs
//! `simpleFoam`, and the decomposition for the processor directories.

use super::*;

/// Writes the minimal `system/` files that are absent.
pub(super) fn write_system(case: &Path, p: usize) -> Result<()> {
    let sys = case.join("system");
    fs::create_dir_all(&sys).map_err(|e| io_err(&sys, e))?;
    let mut files = vec![
        ("controlDict", CONTROL_DICT.to_string()),
        ("fvSchemes", FV_SCHEMES.to_string()),
        ("fvSolution", FV_SOLUTION.to_string()),
    ];
    if p > 1 {
        files.push((
            "decomposeParDict",
            format!("numberOfSubdomains {p};\n\nmethod          scotch;\n"),
        ));
    }
    for (name, body) in files {
        let path = sys.join(name);
        if path.exists() {
            continue;
        }
        let mut text = Vec::new();
        header(
            &mut text,
            FoamFormat::Ascii,
            "dictionary",
            "system",
            name,
            None,
        )
        .and_then(|_| text.write_all(body.as_bytes()))
        .map_err(|e| io_err(&path, e))?;
        fs::write(&path, text).map_err(|e| io_err(&path, e))?;
    }
    Ok(())
}

pub(super) const CONTROL_DICT: &str = "application     simpleFoam;

startFrom       latestTime;
startTime       0;
stopAt          endTime;
endTime         500;
deltaT          1;
writeControl    timeStep;
writeInterval   100;
purgeWrite      0;
writeFormat     binary;
writePrecision  8;
writeCompression off;
timeFormat      general;
timePrecision   6;
runTimeModifiable true;
";

pub(super) const FV_SCHEMES: &str = "ddtSchemes
{
    default         steadyState;
}

gradSchemes
{
    default         Gauss linear;
}

divSchemes
{
    default         none;
    div(phi,U)      bounded Gauss linearUpwind grad(U);
    div((nuEff*dev2(T(grad(U))))) Gauss linear;
    div(div(phi,U)) Gauss linear;
}

laplacianSchemes
{
    default         Gauss linear corrected;
}

interpolationSchemes
{
    default         linear;
}

snGradSchemes
{
    default         corrected;
}
";

pub(super) const FV_SOLUTION: &str = "solvers
{
    p
    {
        solver          GAMG;
        smoother        GaussSeidel;
        tolerance       1e-7;
        relTol          0.01;
    }

    Phi
    {
        $p;
    }

    U
    {
        solver          smoothSolver;
        smoother        GaussSeidel;
        tolerance       1e-8;
        relTol          0.1;
    }
}

SIMPLE
{
    nNonOrthogonalCorrectors 0;
    consistent      yes;
}

potentialFlow
{
    nNonOrthogonalCorrectors 3;
}

relaxationFactors
{
    equations
    {
        U               0.9;
        \".*\"            0.9;
    }
}
";
